//! Result files' JSON read with serde_json, each list of numbers in the document's tables given as
//! one numpy array (as the binary formats hold it) instead of millions of Python numbers. The
//! numbers go straight into vectors as serde_json reads them: no tree of JSON values is built.

use std::fmt;

use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList, PyString};
use serde::de::{self, Deserialize, DeserializeSeed, Deserializer, MapAccess, SeqAccess, Visitor};

/// The JSON document `text` holds, or None if serde_json does not read it (the caller then reads
/// it its own way and names what is wrong). Under objects, reached through objects only (a list
/// of tables is not searched), a non-empty list of numbers is a 1-D array (int64 if every number
/// is an integer, else float64) and a non-empty list of equal-length lists of numbers a 2-D one;
/// everything else is what `json.loads` gives.
#[pyfunction]
pub fn read_json<'py>(py: Python<'py>, text: &[u8]) -> PyResult<Option<Bound<'py, PyAny>>> {
    let Ok(node) = py.detach(|| serde_json::from_slice::<Node>(text)) else {
        return Ok(None);
    };
    to_python(py, node, true).map(Some)
}

/// A JSON value as read, its non-empty lists of numbers kept as vectors.
enum Node {
    Null,
    Bool(bool),
    Int(i64),
    /// An integer past i64 (Python's int keeps it exact; never part of an array).
    Big(u64),
    Float(f64),
    Str(String),
    List(Vec<Node>),
    Ints(Vec<i64>),
    Floats(Vec<f64>),
    /// A non-empty list of equally long non-empty lists of numbers, row after row.
    Table(usize, Vec<Number>),
    Object(Vec<(String, Node)>),
}

#[derive(Clone, Copy)]
enum Number {
    Int(i64),
    Float(f64),
}

impl Number {
    fn node(self) -> Node {
        match self {
            Number::Int(i) => Node::Int(i),
            Number::Float(x) => Node::Float(x),
        }
    }

    fn float(self) -> f64 {
        match self {
            Number::Int(i) => i as f64,
            Number::Float(x) => x,
        }
    }
}

/// A list of numbers as one node: integers if all are, else floats (the rule for every list of
/// numbers, a table's rows included).
fn numbers_node(numbers: &[Number]) -> Node {
    let integers: Option<Vec<i64>> = numbers
        .iter()
        .map(|n| match n {
            Number::Int(i) => Some(*i),
            Number::Float(_) => None,
        })
        .collect();
    match integers {
        Some(values) => Node::Ints(values),
        None => Node::Floats(numbers.iter().map(|n| n.float()).collect()),
    }
}

struct NodeVisitor;

impl<'de> Visitor<'de> for NodeVisitor {
    type Value = Node;

    fn expecting(&self, formatter: &mut fmt::Formatter) -> fmt::Result {
        formatter.write_str("a JSON value")
    }

    fn visit_unit<E>(self) -> Result<Node, E> {
        Ok(Node::Null)
    }

    fn visit_bool<E>(self, value: bool) -> Result<Node, E> {
        Ok(Node::Bool(value))
    }

    fn visit_i64<E>(self, value: i64) -> Result<Node, E> {
        Ok(Node::Int(value))
    }

    fn visit_u64<E>(self, value: u64) -> Result<Node, E> {
        Ok(i64::try_from(value).map_or(Node::Big(value), Node::Int))
    }

    fn visit_f64<E>(self, value: f64) -> Result<Node, E> {
        Ok(Node::Float(value))
    }

    fn visit_str<E>(self, value: &str) -> Result<Node, E> {
        Ok(Node::Str(value.to_owned()))
    }

    fn visit_string<E>(self, value: String) -> Result<Node, E> {
        Ok(Node::Str(value))
    }

    /// Numbers are gathered as one list of numbers, lists of numbers as the rows of one table (read
    /// straight into [`Rows`]); the first element of another kind turns the list into nodes.
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Node, A::Error> {
        let (mut numbers, mut rows, mut nodes) = (Vec::new(), Rows::default(), Vec::new());
        while let Some(element) = seq.next_element_seed(Element(&mut rows))? {
            match element {
                Read::Number(n) if nodes.is_empty() && rows.lengths.is_empty() => numbers.push(n),
                Read::Row if nodes.is_empty() && numbers.is_empty() => {}
                other => {
                    if nodes.is_empty() {
                        // the first element of another kind: those before it become nodes
                        nodes.extend(numbers.drain(..).map(Number::node));
                        let before = rows.lengths.len() - usize::from(matches!(other, Read::Row));
                        nodes.extend(rows.take(before));
                    }
                    match other {
                        Read::Number(n) => nodes.push(n.node()),
                        Read::Row => nodes.extend(rows.take(1)),
                        Read::Value(node) => nodes.push(node),
                    }
                }
            }
        }
        let width = rows.lengths.first().copied().unwrap_or(0);
        Ok(if !numbers.is_empty() {
            numbers_node(&numbers)
        } else if width > 0 && rows.lengths.iter().all(|&length| length == width) {
            Node::Table(width, rows.numbers)
        } else {
            nodes.extend(rows.take(rows.lengths.len()));
            Node::List(nodes)
        })
    }

    fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Node, A::Error> {
        let mut members = Vec::new();
        while let Some((key, value)) = map.next_entry::<String, Node>()? {
            members.push((key, value));
        }
        Ok(Node::Object(members))
    }
}

/// The lists of numbers among a list's elements, read straight into one vector with each one's
/// length: a table of 10^6 rows is then not 10^6 small vectors.
#[derive(Default)]
struct Rows {
    numbers: Vec<Number>,
    lengths: Vec<usize>,
}

impl Rows {
    /// The first `count` rows, taken off, as nodes.
    fn take(&mut self, count: usize) -> Vec<Node> {
        let mut end = 0;
        let rows = self
            .lengths
            .drain(..count)
            .map(|length| {
                end += length;
                numbers_node(&self.numbers[end - length..end])
            })
            .collect();
        self.numbers.drain(..end);
        rows
    }
}

/// One element of a list, as [`Element`] reads it.
enum Read {
    Number(Number),
    /// A non-empty list of numbers, now the last row of the list's [`Rows`].
    Row,
    Value(Node),
}

/// A node read on its own as an element: a number apart, anything else a value.
fn read(node: Node) -> Read {
    match node {
        Node::Int(i) => Read::Number(Number::Int(i)),
        Node::Float(x) => Read::Number(Number::Float(x)),
        other => Read::Value(other),
    }
}

/// Reads one element of a list, a list of numbers into the list's rows.
struct Element<'a>(&'a mut Rows);

impl<'de> DeserializeSeed<'de> for Element<'_> {
    type Value = Read;

    fn deserialize<D: Deserializer<'de>>(self, deserializer: D) -> Result<Read, D::Error> {
        deserializer.deserialize_any(self)
    }
}

impl<'de> Visitor<'de> for Element<'_> {
    type Value = Read;

    fn expecting(&self, formatter: &mut fmt::Formatter) -> fmt::Result {
        formatter.write_str("a JSON value")
    }

    // (scalars as a node reads them: a number is kept apart, anything else is a value)
    fn visit_unit<E: de::Error>(self) -> Result<Read, E> {
        NodeVisitor.visit_unit().map(read)
    }

    fn visit_bool<E: de::Error>(self, value: bool) -> Result<Read, E> {
        NodeVisitor.visit_bool(value).map(read)
    }

    fn visit_i64<E: de::Error>(self, value: i64) -> Result<Read, E> {
        NodeVisitor.visit_i64(value).map(read)
    }

    fn visit_u64<E: de::Error>(self, value: u64) -> Result<Read, E> {
        NodeVisitor.visit_u64(value).map(read)
    }

    fn visit_f64<E: de::Error>(self, value: f64) -> Result<Read, E> {
        NodeVisitor.visit_f64(value).map(read)
    }

    fn visit_str<E: de::Error>(self, value: &str) -> Result<Read, E> {
        NodeVisitor.visit_str(value).map(read)
    }

    fn visit_string<E: de::Error>(self, value: String) -> Result<Read, E> {
        NodeVisitor.visit_string(value).map(read)
    }

    fn visit_map<A: MapAccess<'de>>(self, map: A) -> Result<Read, A::Error> {
        NodeVisitor.visit_map(map).map(Read::Value)
    }

    /// A list of numbers goes on the rows; the first element that is not a number turns it into
    /// an ordinary list (its numbers taken back off the rows).
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Read, A::Error> {
        let rows = self.0;
        let start = rows.numbers.len();
        while let Some(node) = seq.next_element::<Node>()? {
            match node {
                Node::Int(i) => rows.numbers.push(Number::Int(i)),
                Node::Float(x) => rows.numbers.push(Number::Float(x)),
                other => {
                    let mut items: Vec<Node> = rows.numbers.drain(start..).map(Number::node).collect();
                    items.push(other);
                    while let Some(node) = seq.next_element::<Node>()? {
                        items.push(node);
                    }
                    return Ok(Read::Value(Node::List(items)));
                }
            }
        }
        if rows.numbers.len() == start {
            return Ok(Read::Value(Node::List(Vec::new())));
        }
        rows.lengths.push(rows.numbers.len() - start);
        Ok(Read::Row)
    }
}

impl<'de> Deserialize<'de> for Node {
    fn deserialize<D: Deserializer<'de>>(deserializer: D) -> Result<Node, D::Error> {
        deserializer.deserialize_any(NodeVisitor)
    }
}

fn to_python(py: Python<'_>, node: Node, arrays: bool) -> PyResult<Bound<'_, PyAny>> {
    Ok(match node {
        Node::Null => py.None().into_bound(py),
        Node::Bool(b) => PyBool::new(py, b).to_owned().into_any(),
        Node::Int(i) => i.into_pyobject(py)?.into_any(),
        Node::Big(u) => u.into_pyobject(py)?.into_any(),
        Node::Float(x) => x.into_pyobject(py)?.into_any(),
        Node::Str(text) => PyString::new(py, &text).into_any(),
        Node::Ints(values) if arrays => PyArray1::from_vec(py, values).into_any(),
        Node::Floats(values) if arrays => PyArray1::from_vec(py, values).into_any(),
        Node::Ints(values) => PyList::new(py, values)?.into_any(),
        Node::Floats(values) => PyList::new(py, values)?.into_any(),
        Node::Table(width, numbers) if arrays => table(py, width, &numbers)?,
        Node::Table(width, numbers) => {
            let list = PyList::empty(py);
            for row in numbers.chunks(width) {
                list.append(to_python(py, numbers_node(row), false)?)?;
            }
            list.into_any()
        }
        Node::List(items) => {
            let list = PyList::empty(py);
            for item in items {
                list.append(to_python(py, item, false)?)?;
            }
            list.into_any()
        }
        Node::Object(members) => {
            let dict = PyDict::new(py);
            for (key, item) in members {
                dict.set_item(key, to_python(py, item, arrays)?)?;
            }
            dict.into_any()
        }
    })
}

/// A table as one 2-D array: int64 if every number is an integer, else float64.
fn table<'py>(py: Python<'py>, width: usize, numbers: &[Number]) -> PyResult<Bound<'py, PyAny>> {
    let shape = [numbers.len() / width, width];
    Ok(match numbers_node(numbers) {
        Node::Ints(values) => PyArray1::from_vec(py, values).reshape(shape)?.into_any(),
        Node::Floats(values) => PyArray1::from_vec(py, values).reshape(shape)?.into_any(),
        _ => unreachable!("a list of numbers is integers or floats"),
    })
}
