//! A small S-expression parser for rcssservermj's messages: lists in parentheses, atoms
//! separated by whitespace or parentheses, no quoting (the server has none).
//!
//! Atoms borrow from the input; only lists allocate (one `Vec` each). Parsing is iterative with
//! an explicit stack and a nesting limit, so a hostile `((((…` costs neither the call stack nor
//! unbounded memory, and dropping the tree (which recurses) stays shallow.

use thiserror::Error;

/// The nesting limit for agent messages: perceptions nest at most 4 deep (`(See (P (head (pol
/// …))))`).
pub const PERCEPTION_MAX_DEPTH: usize = 16;

/// The nesting limit for monitor messages: the scene graph nests one level per body of the
/// deepest kinematic chain plus geometry nodes (measured 15 with two T1s).
pub const MONITOR_MAX_DEPTH: usize = 128;

/// One S-expression: an atom or a list of expressions.
#[derive(Debug, Clone, PartialEq)]
pub enum Sexp<'a> {
    /// A token, borrowed from the input.
    Atom(&'a str),
    /// A parenthesised list.
    List(Vec<Sexp<'a>>),
}

/// What was wrong with a text that is not a sequence of S-expressions, and at which byte.
#[derive(Debug, Clone, PartialEq, Eq, Error)]
pub enum SexpError {
    /// The bytes are not UTF-8 (the server encodes every message as UTF-8).
    #[error("invalid UTF-8 at byte {offset}")]
    InvalidUtf8 {
        /// Offset of the first invalid byte.
        offset: usize,
    },
    /// A `)` closes no list.
    #[error("unexpected ')' at byte {offset}")]
    UnexpectedClose {
        /// Offset of the `)`.
        offset: usize,
    },
    /// The input ended inside a list.
    #[error("the list opened at byte {offset} is not closed")]
    Unclosed {
        /// Offset of the `(` of the innermost unclosed list.
        offset: usize,
    },
    /// Lists nest deeper than the limit.
    #[error("lists nest deeper than {max} levels at byte {offset}")]
    TooDeep {
        /// Offset of the `(` that went past the limit.
        offset: usize,
        /// The limit.
        max: usize,
    },
    /// An atom outside any list (a message is a sequence of lists).
    #[error("an atom outside any list at byte {offset}")]
    TopLevelAtom {
        /// Offset of the atom.
        offset: usize,
    },
}

impl<'a> Sexp<'a> {
    /// The atom's text, if this is an atom.
    pub fn as_atom(&self) -> Option<&'a str> {
        match self {
            Sexp::Atom(text) => Some(text),
            Sexp::List(_) => None,
        }
    }

    /// The list's items, if this is a list.
    pub fn as_list(&self) -> Option<&[Sexp<'a>]> {
        match self {
            Sexp::List(items) => Some(items),
            Sexp::Atom(_) => None,
        }
    }

    /// The first item of a list when it is an atom: the name of a perceptor, effector or field.
    pub fn head(&self) -> Option<&'a str> {
        self.as_list()?.first()?.as_atom()
    }
}

/// Parses `input` as a sequence of lists (`(time …)(GS …)…`), nesting at most `max_depth`.
pub fn parse(input: &[u8], max_depth: usize) -> Result<Vec<Sexp<'_>>, SexpError> {
    let text = std::str::from_utf8(input)
        .map_err(|e| SexpError::InvalidUtf8 { offset: e.valid_up_to() })?;
    let bytes = text.as_bytes();
    let mut top: Vec<Sexp<'_>> = Vec::new();
    // Open lists, innermost last, each with the offset of its `(` for error messages.
    let mut open: Vec<(Vec<Sexp<'_>>, usize)> = Vec::new();
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'(' => {
                if open.len() >= max_depth {
                    return Err(SexpError::TooDeep { offset: i, max: max_depth });
                }
                open.push((Vec::new(), i));
                i += 1;
            }
            b')' => {
                let Some((items, _)) = open.pop() else {
                    return Err(SexpError::UnexpectedClose { offset: i });
                };
                match open.last_mut() {
                    Some((parent, _)) => parent.push(Sexp::List(items)),
                    None => top.push(Sexp::List(items)),
                }
                i += 1;
            }
            b' ' | b'\t' | b'\n' | b'\r' => i += 1,
            _ => {
                let start = i;
                while i < bytes.len()
                    && !matches!(bytes[i], b'(' | b')' | b' ' | b'\t' | b'\n' | b'\r')
                {
                    i += 1;
                }
                let Some((parent, _)) = open.last_mut() else {
                    return Err(SexpError::TopLevelAtom { offset: start });
                };
                // The delimiters are ASCII, so `start..i` lies on character boundaries.
                parent.push(Sexp::Atom(&text[start..i]));
            }
        }
    }
    if let Some((_, offset)) = open.last() {
        return Err(SexpError::Unclosed { offset: *offset });
    }
    Ok(top)
}
