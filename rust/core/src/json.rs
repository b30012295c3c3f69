//! A reader of result files' JSON: the document as a tree in which every list of numbers that is
//! a value of an object reached from the top through objects only (the rule by which the binary
//! result files store arrays) is an array: 1-D, or 2-D for a list of equal-length lists of
//! numbers. A 10^6-node result is then a few dozen arrays instead of millions of numbers, each a
//! Python object, and lists of them.
//!
//! Only plain, valid JSON is read; anything else gives None, and the caller reads the text in
//! its usual way (which also says what is wrong with it): invalid UTF-8 or JSON, an integer beyond
//! 64 bits, a number beyond the floats, a lone surrogate escape, nesting deeper than [`MAX_DEPTH`].
//! A list of booleans, or of numbers mixed with anything else, stays a list, as a reader of lists
//! would name its entries.

/// Nesting beyond which a document is left to the caller's reader.
pub const MAX_DEPTH: usize = 512;

/// A JSON value; objects keep their members in order (a repeated key included).
#[derive(Clone, Debug, PartialEq)]
pub enum Value {
    Null,
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    List(Vec<Value>),
    Object(Vec<(String, Value)>),
    /// A list of numbers (`columns` None) or of `columns` numbers each (row after row): floats if
    /// any number is a float, else integers.
    Floats(Vec<f64>, Option<usize>),
    Ints(Vec<i64>, Option<usize>),
}

/// The document `text` holds, or None if it is not plain valid JSON (see the module's text).
pub fn read(text: &[u8]) -> Option<Value> {
    std::str::from_utf8(text).ok()?;
    let mut reader = Reader { text, at: 0 };
    let value = reader.value(0, Place::Top)?;
    reader.space();
    (reader.at == text.len()).then_some(value)
}

/// Where a value is: whether an object there is searched for arrays, a list there may be one.
#[derive(Clone, Copy, PartialEq)]
enum Place {
    Top,
    /// A member of a searched object (the top one, and its members' objects).
    Member,
    /// In a list, or below one.
    Inside,
}

struct Reader<'a> {
    text: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn peek(&self) -> Option<u8> {
        self.text.get(self.at).copied()
    }

    fn space(&mut self) {
        while matches!(self.peek(), Some(b' ' | b'\t' | b'\n' | b'\r')) {
            self.at += 1;
        }
    }

    fn literal(&mut self, word: &[u8], value: Value) -> Option<Value> {
        let found = self.text.get(self.at..self.at + word.len())? == word;
        self.at += word.len();
        found.then_some(value)
    }

    fn value(&mut self, depth: usize, place: Place) -> Option<Value> {
        if depth > MAX_DEPTH {
            return None;
        }
        self.space();
        match self.peek()? {
            b'{' => self.object(depth, place != Place::Inside),
            b'[' => {
                let start = self.at;
                if place == Place::Member {
                    if let Some(array) = self.array() {
                        return Some(array);
                    }
                    self.at = start; // not an array: read it as a list
                }
                self.list(depth).map(Value::List)
            }
            b'"' => self.string().map(Value::Str),
            b't' => self.literal(b"true", Value::Bool(true)),
            b'f' => self.literal(b"false", Value::Bool(false)),
            b'n' => self.literal(b"null", Value::Null),
            _ => self.number(),
        }
    }

    /// An object; `searched`: whether its members' lists may be arrays.
    fn object(&mut self, depth: usize, searched: bool) -> Option<Value> {
        self.at += 1; // '{'
        let mut members = Vec::new();
        self.space();
        if self.peek()? == b'}' {
            self.at += 1;
            return Some(Value::Object(members));
        }
        loop {
            self.space();
            if self.peek()? != b'"' {
                return None;
            }
            let key = self.string()?;
            self.space();
            if self.peek()? != b':' {
                return None;
            }
            self.at += 1;
            let place = if searched { Place::Member } else { Place::Inside };
            members.push((key, self.value(depth + 1, place)?));
            self.space();
            match self.peek()? {
                b',' => self.at += 1,
                b'}' => {
                    self.at += 1;
                    return Some(Value::Object(members));
                }
                _ => return None,
            }
        }
    }

    /// A list's items (no array: nothing inside a list is searched for arrays but its rows).
    fn list(&mut self, depth: usize) -> Option<Vec<Value>> {
        self.at += 1; // '['
        let mut items = Vec::new();
        self.space();
        if self.peek()? == b']' {
            self.at += 1;
            return Some(items);
        }
        loop {
            items.push(self.value(depth + 1, Place::Inside)?);
            self.space();
            match self.peek()? {
                b',' => self.at += 1,
                b']' => {
                    self.at += 1;
                    return Some(items);
                }
                _ => return None,
            }
        }
    }

    fn string(&mut self) -> Option<String> {
        self.at += 1; // '"'
        let mut text = String::new();
        loop {
            let start = self.at;
            while let Some(byte) = self.peek() {
                if byte == b'"' || byte == b'\\' || byte < 0x20 {
                    break;
                }
                self.at += 1;
            }
            // (valid UTF-8 as a whole, and cut only at ASCII bytes)
            text.push_str(std::str::from_utf8(&self.text[start..self.at]).ok()?);
            match self.peek()? {
                b'"' => {
                    self.at += 1;
                    return Some(text);
                }
                b'\\' => {
                    self.at += 1;
                    let escaped = match self.peek()? {
                        b'"' => '"',
                        b'\\' => '\\',
                        b'/' => '/',
                        b'b' => '\u{8}',
                        b'f' => '\u{c}',
                        b'n' => '\n',
                        b'r' => '\r',
                        b't' => '\t',
                        b'u' => {
                            self.at += 1;
                            let unit = self.hex4()?;
                            self.at -= 1; // (the common step below)
                            self.unicode(unit)?
                        }
                        _ => return None,
                    };
                    self.at += 1;
                    text.push(escaped);
                }
                _ => return None, // a raw control character
            }
        }
    }

    /// Four hex digits at the reader, as a number; the reader after them.
    fn hex4(&mut self) -> Option<u32> {
        let digits = std::str::from_utf8(self.text.get(self.at..self.at + 4)?).ok()?;
        if !digits.bytes().all(|b| b.is_ascii_hexdigit()) {
            return None;
        }
        self.at += 4;
        u32::from_str_radix(digits, 16).ok()
    }

    /// The character of a `\u` escape `unit` (the reader on its last digit), with the low half of
    /// a surrogate pair after it; None for a lone surrogate.
    fn unicode(&mut self, unit: u32) -> Option<char> {
        if (0xDC00..0xE000).contains(&unit) {
            return None;
        }
        if !(0xD800..0xDC00).contains(&unit) {
            return char::from_u32(unit);
        }
        let next = self.at + 1;
        if self.text.get(next..next + 2)? != b"\\u" {
            return None;
        }
        self.at = next + 2;
        let low = self.hex4()?;
        self.at -= 1;
        if !(0xDC00..0xE000).contains(&low) {
            return None;
        }
        char::from_u32(0x10000 + ((unit - 0xD800) << 10) + (low - 0xDC00))
    }

    fn digits(&mut self) -> usize {
        let start = self.at;
        while matches!(self.peek(), Some(b'0'..=b'9')) {
            self.at += 1;
        }
        self.at - start
    }

    /// A number by JSON's grammar: an integer (64 bits) without fraction or exponent, else a float.
    fn number(&mut self) -> Option<Value> {
        let start = self.at;
        if self.peek() == Some(b'-') {
            self.at += 1;
        }
        let leading_zero = self.peek() == Some(b'0');
        let whole = self.digits();
        if whole == 0 || (leading_zero && whole > 1) {
            return None;
        }
        let mut integer = true;
        if self.peek() == Some(b'.') {
            self.at += 1;
            if self.digits() == 0 {
                return None;
            }
            integer = false;
        }
        if matches!(self.peek(), Some(b'e' | b'E')) {
            self.at += 1;
            if matches!(self.peek(), Some(b'+' | b'-')) {
                self.at += 1;
            }
            if self.digits() == 0 {
                return None;
            }
            integer = false;
        }
        let text = std::str::from_utf8(&self.text[start..self.at]).ok()?;
        if integer {
            return text.parse().ok().map(Value::Int);
        }
        let value: f64 = text.parse().ok()?;
        value.is_finite().then_some(Value::Float(value))
    }
}

/// A list's numbers: integers while they all are, floats from the first float on.
enum Numbers {
    Ints(Vec<i64>),
    Floats(Vec<f64>),
}

impl Numbers {
    fn push(&mut self, number: Value) {
        match (&mut *self, number) {
            (Numbers::Ints(ints), Value::Int(i)) => ints.push(i),
            (Numbers::Floats(floats), Value::Int(i)) => floats.push(i as f64), // (to nearest, as Python's float(int))
            (Numbers::Floats(floats), Value::Float(x)) => floats.push(x),
            (Numbers::Ints(ints), Value::Float(x)) => {
                let mut floats = Vec::with_capacity(ints.capacity());
                floats.extend(ints.iter().map(|&i| i as f64));
                floats.push(x);
                *self = Numbers::Floats(floats);
            }
            _ => unreachable!("only numbers are pushed"),
        }
    }

    fn len(&self) -> usize {
        match self {
            Numbers::Ints(ints) => ints.len(),
            Numbers::Floats(floats) => floats.len(),
        }
    }

    fn array(self, columns: Option<usize>) -> Value {
        match self {
            Numbers::Ints(ints) => Value::Ints(ints, columns),
            Numbers::Floats(floats) => Value::Floats(floats, columns),
        }
    }
}

impl Reader<'_> {
    /// The list at the reader as an array: numbers (no booleans), or equal-length non-empty lists
    /// of numbers; None (the reader anywhere) if it is not one.
    fn array(&mut self) -> Option<Value> {
        let mut numbers = Numbers::Ints(Vec::with_capacity(self.count()));
        self.at += 1; // '['
        self.space();
        if self.peek()? != b'[' {
            self.at -= 1;
            self.numbers(&mut numbers)?;
            return Some(numbers.array(None));
        }
        let mut columns = None;
        loop {
            self.space();
            if self.peek()? != b'[' {
                return None;
            }
            let before = numbers.len();
            self.numbers(&mut numbers)?;
            let width = numbers.len() - before;
            if *columns.get_or_insert(width) != width {
                return None;
            }
            self.space();
            match self.peek()? {
                b',' => self.at += 1,
                b']' => {
                    self.at += 1;
                    return Some(numbers.array(columns));
                }
                _ => return None,
            }
        }
    }

    /// How many numbers the list at the reader holds if it is an array (its commas plus one, in
    /// one list or in rows), so that it is allocated once: grown, it would be copied into fresh
    /// memory at each doubling. 0 if it holds a string or an object.
    fn count(&self) -> usize {
        let (mut depth, mut commas) = (0usize, 0);
        for &byte in &self.text[self.at..] {
            match byte {
                b'[' => depth += 1,
                b']' => {
                    depth -= 1;
                    if depth == 0 {
                        break;
                    }
                }
                b',' => commas += 1,
                b'"' | b'{' => return 0,
                _ => {}
            }
        }
        commas + 1
    }

    /// A non-empty list of numbers at the reader, onto `numbers`.
    fn numbers(&mut self, numbers: &mut Numbers) -> Option<()> {
        self.at += 1; // '['
        loop {
            self.space();
            numbers.push(self.number()?);
            self.space();
            match self.peek()? {
                b',' => self.at += 1,
                b']' => {
                    self.at += 1;
                    return Some(());
                }
                _ => return None,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn object(members: Vec<(&str, Value)>) -> Value {
        Value::Object(members.into_iter().map(|(k, v)| (k.to_string(), v)).collect())
    }

    #[test]
    fn lists_of_numbers_under_objects_are_arrays() {
        let text = br#"{"x": [1, 2.5, -0.0], "n": [3, -4], "p": {"r": [[1, 2], [3, 4]]}, "b": [true]}"#;
        let expected = object(vec![
            ("x", Value::Floats(vec![1.0, 2.5, -0.0], None)),
            ("n", Value::Ints(vec![3, -4], None)),
            ("p", object(vec![("r", Value::Ints(vec![1, 2, 3, 4], Some(2)))])),
            ("b", Value::List(vec![Value::Bool(true)])),
        ]);
        assert_eq!(read(text), Some(expected));
    }

    #[test]
    fn inside_lists_nothing_is_an_array() {
        let text = br#"{"s": [{"node": 0, "force": [0.5, 1]}], "m": [[1, 2], [3]], "e": [], "q": [[]]}"#;
        let row = |items: Vec<Value>| Value::List(items);
        let expected = object(vec![
            (
                "s",
                row(vec![object(vec![
                    ("node", Value::Int(0)),
                    ("force", row(vec![Value::Float(0.5), Value::Int(1)])),
                ])]),
            ),
            (
                "m",
                row(vec![
                    row(vec![Value::Int(1), Value::Int(2)]),
                    row(vec![Value::Int(3)]),
                ]),
            ),
            ("e", row(vec![])),
            ("q", row(vec![row(vec![])])),
        ]);
        assert_eq!(read(text), Some(expected));
        assert_eq!(read(b"[1, 2]"), Some(row(vec![Value::Int(1), Value::Int(2)])));
    }

    #[test]
    fn strings_numbers_and_literals_read_as_json_says() {
        let text = "{\"a\\\"b\": \"\\u00e9\\ud83d\\ude00\\n\u{e9}\", \"t\": [null, false, 1e2, -12, 0.5E-1]}";
        let expected = object(vec![
            ("a\"b", Value::Str("\u{e9}\u{1F600}\n\u{e9}".to_string())),
            (
                "t",
                Value::List(vec![
                    Value::Null,
                    Value::Bool(false),
                    Value::Float(100.0),
                    Value::Int(-12),
                    Value::Float(0.05),
                ]),
            ),
        ]);
        assert_eq!(read(text.as_bytes()), Some(expected));
        assert_eq!(read(b" 0.1 "), Some(Value::Float(0.1)));
    }

    #[test]
    fn anything_but_plain_valid_json_is_left_to_the_caller() {
        for text in [
            &b"{\"x\": [1, 2,]}"[..],
            b"{\"x\": 01}",
            b"{\"x\": 1.}",
            b"{\"x\": .5}",
            b"{\"x\": NaN}",
            b"{\"x\": 1e400}",
            b"{\"x\": 9223372036854775808}",
            b"{\"x\": \"\\ud800\"}",
            b"{\"x\": \"\\q\"}",
            b"{\"x\": \"\x01\"}",
            b"{\"x\": 1} 2",
            b"{\"x\": \xff}",
            b"{x: 1}",
            b"{\"x\" 1}",
            b"",
            b"tru",
        ] {
            assert_eq!(read(text), None, "{}", String::from_utf8_lossy(text));
        }
        let deep = format!("{}{}", "[".repeat(MAX_DEPTH + 2), "]".repeat(MAX_DEPTH + 2));
        assert_eq!(read(deep.as_bytes()), None);
        assert_eq!(
            read(b"{\"x\": 9223372036854775807}"),
            Some(object(vec![("x", Value::Int(i64::MAX))]))
        );
    }
}
