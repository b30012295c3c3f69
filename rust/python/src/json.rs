//! Result files' JSON read with serde_json, each list of numbers in the document's tables given as
//! one numpy array (as the binary formats hold it) instead of millions of Python numbers. The
//! numbers go straight into vectors as serde_json reads them: no tree of JSON values is built.

use std::fmt;

use numpy::{PyArray1, PyArrayMethods};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyList, PyString};
use serde::de::{Deserialize, Deserializer, MapAccess, SeqAccess, Visitor};

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
    Object(Vec<(String, Node)>),
}

impl Node {
    fn numbers(&self) -> Option<usize> {
        match self {
            Node::Ints(values) => Some(values.len()),
            Node::Floats(values) => Some(values.len()),
            _ => None,
        }
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

    /// Numbers are gathered as integers until the first float, then as floats; the first element
    /// that is not a number turns the list into nodes.
    fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<Node, A::Error> {
        let (mut ints, mut floats, mut nodes) = (Vec::new(), Vec::new(), Vec::new());
        let mut numeric = true;
        while let Some(node) = seq.next_element::<Node>()? {
            match node {
                Node::Int(i) if numeric && floats.is_empty() => ints.push(i),
                Node::Int(i) if numeric => floats.push(i as f64),
                Node::Float(x) if numeric => {
                    floats.extend(ints.drain(..).map(|i| i as f64));
                    floats.push(x);
                }
                other => {
                    if numeric {
                        numeric = false;
                        nodes.extend(ints.drain(..).map(Node::Int));
                        nodes.extend(floats.drain(..).map(Node::Float));
                    }
                    nodes.push(other);
                }
            }
        }
        Ok(if !numeric || (ints.is_empty() && floats.is_empty()) {
            Node::List(nodes)
        } else if floats.is_empty() {
            Node::Ints(ints)
        } else {
            Node::Floats(floats)
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
        Node::List(items) if arrays && is_table(&items) => rows(py, items)?,
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

/// Whether `items` are lists of numbers, all of one length.
fn is_table(items: &[Node]) -> bool {
    let width = items.first().and_then(Node::numbers);
    width.is_some() && items.iter().all(|item| item.numbers() == width)
}

/// A table's rows as one 2-D array: int64 if every row is integers, else float64.
fn rows(py: Python<'_>, items: Vec<Node>) -> PyResult<Bound<'_, PyAny>> {
    let shape = [items.len(), items[0].numbers().unwrap_or(0)];
    if items.iter().all(|item| matches!(item, Node::Ints(_))) {
        let mut values = Vec::with_capacity(shape[0] * shape[1]);
        for item in items {
            if let Node::Ints(row) = item {
                values.extend(row);
            }
        }
        return Ok(PyArray1::from_vec(py, values).reshape(shape)?.into_any());
    }
    let mut values = Vec::with_capacity(shape[0] * shape[1]);
    for item in items {
        match item {
            Node::Ints(row) => values.extend(row.into_iter().map(|i| i as f64)),
            Node::Floats(row) => values.extend(row),
            _ => {}
        }
    }
    Ok(PyArray1::from_vec(py, values).reshape(shape)?.into_any())
}
