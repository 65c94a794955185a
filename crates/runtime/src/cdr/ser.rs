//! The CDR writer: a serde `Serializer` that appends values in declaration order, each
//! aligned to its size relative to the start of the payload.

use serde::Serialize;
use serde::ser;

use super::CdrError;

pub(crate) struct Writer<'a> {
    out: &'a mut Vec<u8>,
    /// Where the payload starts in `out`: alignment counts from here.
    base: usize,
}

impl<'a> Writer<'a> {
    pub(crate) fn new(out: &'a mut Vec<u8>, base: usize) -> Writer<'a> {
        Writer { out, base }
    }

    #[inline]
    fn pad(&mut self, align: usize) {
        let misalignment = (self.out.len() - self.base) & (align - 1);
        if misalignment != 0 {
            // Eight zeros written and the excess cut: one store. Copying a variable number of
            // zeros (or `resize`) compiles to a call of `memset`, which took 1.6 % of a logging
            // match thread's samples for these few bytes.
            let padded = self.out.len() + align - misalignment;
            self.out.extend_from_slice(&[0; 8]);
            self.out.truncate(padded);
        }
    }

    #[inline]
    fn put<const N: usize>(&mut self, bytes: [u8; N]) {
        self.pad(N);
        self.out.extend_from_slice(&bytes);
    }

    #[inline]
    fn put_len(&mut self, len: usize) -> Result<(), CdrError> {
        let len = u32::try_from(len).map_err(|_| CdrError::TooLong(len))?;
        self.put(len.to_le_bytes());
        Ok(())
    }

    /// A count written before its elements are: a place for it now, filled in at the end.
    #[inline]
    fn reserve_count(&mut self) -> usize {
        self.pad(4);
        let at = self.out.len();
        self.out.extend_from_slice(&[0; 4]);
        at
    }
}

/// A compound value being written; `count`: where its element count goes when the count was
/// not known in advance, and how many elements came.
pub(crate) struct Compound<'w, 'a> {
    writer: &'w mut Writer<'a>,
    count: Option<(usize, usize)>,
}

impl Compound<'_, '_> {
    fn element(&mut self) {
        if let Some((_, n)) = &mut self.count {
            *n += 1;
        }
    }

    #[inline]
    fn end(self) -> Result<(), CdrError> {
        if let Some((at, n)) = self.count {
            let n = u32::try_from(n).map_err(|_| CdrError::TooLong(n))?;
            self.writer.out[at..at + 4].copy_from_slice(&n.to_le_bytes());
        }
        Ok(())
    }
}

// The methods are `#[inline]`: a logging match encodes about four thousand small packages per
// simulated second on its own thread, and a call per field (with its `Result` returned through
// memory) cost the match more than the writing itself.
impl<'w, 'a> ser::Serializer for &'w mut Writer<'a> {
    type Ok = ();
    type Error = CdrError;
    type SerializeSeq = Compound<'w, 'a>;
    type SerializeTuple = Compound<'w, 'a>;
    type SerializeTupleStruct = Compound<'w, 'a>;
    type SerializeTupleVariant = Compound<'w, 'a>;
    type SerializeMap = Compound<'w, 'a>;
    type SerializeStruct = Compound<'w, 'a>;
    type SerializeStructVariant = Compound<'w, 'a>;

    fn is_human_readable(&self) -> bool {
        false
    }

    #[inline]
    fn serialize_bool(self, v: bool) -> Result<(), CdrError> {
        self.out.push(u8::from(v));
        Ok(())
    }

    #[inline]
    fn serialize_i8(self, v: i8) -> Result<(), CdrError> {
        self.put(v.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_i16(self, v: i16) -> Result<(), CdrError> {
        self.put(v.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_i32(self, v: i32) -> Result<(), CdrError> {
        self.put(v.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_i64(self, v: i64) -> Result<(), CdrError> {
        self.put(v.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_u8(self, v: u8) -> Result<(), CdrError> {
        self.out.push(v);
        Ok(())
    }

    #[inline]
    fn serialize_u16(self, v: u16) -> Result<(), CdrError> {
        self.put(v.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_u32(self, v: u32) -> Result<(), CdrError> {
        self.put(v.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_u64(self, v: u64) -> Result<(), CdrError> {
        self.put(v.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_i128(self, _: i128) -> Result<(), CdrError> {
        Err(CdrError::Unsupported("a 128-bit integer"))
    }

    #[inline]
    fn serialize_u128(self, _: u128) -> Result<(), CdrError> {
        Err(CdrError::Unsupported("a 128-bit integer"))
    }

    #[inline]
    fn serialize_f32(self, v: f32) -> Result<(), CdrError> {
        self.put(v.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_f64(self, v: f64) -> Result<(), CdrError> {
        self.put(v.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_char(self, v: char) -> Result<(), CdrError> {
        self.put(u32::from(v).to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_str(self, v: &str) -> Result<(), CdrError> {
        self.put_len(v.len() + 1)?;
        self.out.extend_from_slice(v.as_bytes());
        self.out.push(0);
        Ok(())
    }

    #[inline]
    fn serialize_bytes(self, v: &[u8]) -> Result<(), CdrError> {
        self.put_len(v.len())?;
        self.out.extend_from_slice(v);
        Ok(())
    }

    #[inline]
    fn serialize_none(self) -> Result<(), CdrError> {
        self.put(0u32.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_some<T: Serialize + ?Sized>(self, value: &T) -> Result<(), CdrError> {
        self.put(1u32.to_le_bytes());
        value.serialize(self)
    }

    #[inline]
    fn serialize_unit(self) -> Result<(), CdrError> {
        Ok(())
    }

    #[inline]
    fn serialize_unit_struct(self, _: &'static str) -> Result<(), CdrError> {
        Ok(())
    }

    #[inline]
    fn serialize_unit_variant(
        self,
        _: &'static str,
        index: u32,
        _: &'static str,
    ) -> Result<(), CdrError> {
        self.put(index.to_le_bytes());
        Ok(())
    }

    #[inline]
    fn serialize_newtype_struct<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        value: &T,
    ) -> Result<(), CdrError> {
        value.serialize(self)
    }

    #[inline]
    fn serialize_newtype_variant<T: Serialize + ?Sized>(
        self,
        _: &'static str,
        index: u32,
        _: &'static str,
        value: &T,
    ) -> Result<(), CdrError> {
        self.put(index.to_le_bytes());
        value.serialize(self)
    }

    #[inline]
    fn serialize_seq(self, len: Option<usize>) -> Result<Compound<'w, 'a>, CdrError> {
        let count = match len {
            Some(len) => {
                self.put_len(len)?;
                None
            }
            None => Some((self.reserve_count(), 0)),
        };
        Ok(Compound { writer: self, count })
    }

    #[inline]
    fn serialize_tuple(self, _: usize) -> Result<Compound<'w, 'a>, CdrError> {
        Ok(Compound { writer: self, count: None })
    }

    #[inline]
    fn serialize_tuple_struct(
        self,
        _: &'static str,
        _: usize,
    ) -> Result<Compound<'w, 'a>, CdrError> {
        Ok(Compound { writer: self, count: None })
    }

    #[inline]
    fn serialize_tuple_variant(
        self,
        _: &'static str,
        index: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Compound<'w, 'a>, CdrError> {
        self.put(index.to_le_bytes());
        Ok(Compound { writer: self, count: None })
    }

    #[inline]
    fn serialize_map(self, len: Option<usize>) -> Result<Compound<'w, 'a>, CdrError> {
        self.serialize_seq(len)
    }

    #[inline]
    fn serialize_struct(self, _: &'static str, _: usize) -> Result<Compound<'w, 'a>, CdrError> {
        Ok(Compound { writer: self, count: None })
    }

    #[inline]
    fn serialize_struct_variant(
        self,
        _: &'static str,
        index: u32,
        _: &'static str,
        _: usize,
    ) -> Result<Compound<'w, 'a>, CdrError> {
        self.put(index.to_le_bytes());
        Ok(Compound { writer: self, count: None })
    }
}

impl ser::SerializeSeq for Compound<'_, '_> {
    type Ok = ();
    type Error = CdrError;

    #[inline]
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), CdrError> {
        self.element();
        value.serialize(&mut *self.writer)
    }

    #[inline]
    fn end(self) -> Result<(), CdrError> {
        Compound::end(self)
    }
}

impl ser::SerializeTuple for Compound<'_, '_> {
    type Ok = ();
    type Error = CdrError;

    #[inline]
    fn serialize_element<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), CdrError> {
        value.serialize(&mut *self.writer)
    }

    #[inline]
    fn end(self) -> Result<(), CdrError> {
        Ok(())
    }
}

impl ser::SerializeTupleStruct for Compound<'_, '_> {
    type Ok = ();
    type Error = CdrError;

    #[inline]
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), CdrError> {
        value.serialize(&mut *self.writer)
    }

    #[inline]
    fn end(self) -> Result<(), CdrError> {
        Ok(())
    }
}

impl ser::SerializeTupleVariant for Compound<'_, '_> {
    type Ok = ();
    type Error = CdrError;

    #[inline]
    fn serialize_field<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), CdrError> {
        value.serialize(&mut *self.writer)
    }

    #[inline]
    fn end(self) -> Result<(), CdrError> {
        Ok(())
    }
}

impl ser::SerializeMap for Compound<'_, '_> {
    type Ok = ();
    type Error = CdrError;

    #[inline]
    fn serialize_key<T: Serialize + ?Sized>(&mut self, key: &T) -> Result<(), CdrError> {
        self.element();
        key.serialize(&mut *self.writer)
    }

    #[inline]
    fn serialize_value<T: Serialize + ?Sized>(&mut self, value: &T) -> Result<(), CdrError> {
        value.serialize(&mut *self.writer)
    }

    #[inline]
    fn end(self) -> Result<(), CdrError> {
        Compound::end(self)
    }
}

impl ser::SerializeStruct for Compound<'_, '_> {
    type Ok = ();
    type Error = CdrError;

    #[inline]
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        _: &'static str,
        value: &T,
    ) -> Result<(), CdrError> {
        value.serialize(&mut *self.writer)
    }

    fn skip_field(&mut self, key: &'static str) -> Result<(), CdrError> {
        Err(CdrError::SkippedField(key))
    }

    #[inline]
    fn end(self) -> Result<(), CdrError> {
        Ok(())
    }
}

impl ser::SerializeStructVariant for Compound<'_, '_> {
    type Ok = ();
    type Error = CdrError;

    #[inline]
    fn serialize_field<T: Serialize + ?Sized>(
        &mut self,
        _: &'static str,
        value: &T,
    ) -> Result<(), CdrError> {
        value.serialize(&mut *self.writer)
    }

    fn skip_field(&mut self, key: &'static str) -> Result<(), CdrError> {
        Err(CdrError::SkippedField(key))
    }

    #[inline]
    fn end(self) -> Result<(), CdrError> {
        Ok(())
    }
}
