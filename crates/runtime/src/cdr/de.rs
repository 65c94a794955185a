//! The CDR reader: a serde `Deserializer` that reads values in the order the type declares
//! them. It never trusts a length: every count is checked against the bytes that are left.

use serde::de::{self, DeserializeSeed, IntoDeserializer, Visitor};

use super::CdrError;

pub(crate) struct Reader<'de> {
    data: &'de [u8],
    /// Read position, from the start of the payload (alignment counts from there).
    pos: usize,
}

impl<'de> Reader<'de> {
    pub(crate) fn new(data: &'de [u8]) -> Reader<'de> {
        Reader { data, pos: 0 }
    }

    /// Checks that the whole payload was read.
    pub(crate) fn finish(&self) -> Result<(), CdrError> {
        match self.data.len() - self.pos {
            0 => Ok(()),
            left => Err(CdrError::TrailingBytes(left)),
        }
    }

    pub(crate) fn position(&self) -> usize {
        self.pos
    }

    pub(crate) fn remaining(&self) -> usize {
        self.data.len() - self.pos
    }

    pub(crate) fn take(&mut self, n: usize) -> Result<&'de [u8], CdrError> {
        let end = self.pos.checked_add(n).filter(|&end| end <= self.data.len());
        let Some(end) = end else {
            return Err(CdrError::Truncated { offset: self.pos, needed: n });
        };
        let bytes = &self.data[self.pos..end];
        self.pos = end;
        Ok(bytes)
    }

    #[inline]
    fn get<const N: usize>(&mut self) -> Result<[u8; N], CdrError> {
        let misalignment = self.pos & (N - 1);
        if misalignment != 0 {
            self.take(N - misalignment)?;
        }
        let mut out = [0; N];
        out.copy_from_slice(self.take(N)?);
        Ok(out)
    }

    pub(crate) fn bool(&mut self) -> Result<bool, CdrError> {
        let at = self.pos;
        match self.get::<1>()?[0] {
            0 => Ok(false),
            1 => Ok(true),
            other => Err(invalid(at, format!("{other} is not a boolean"))),
        }
    }

    pub(crate) fn u8(&mut self) -> Result<u8, CdrError> {
        Ok(self.get::<1>()?[0])
    }

    pub(crate) fn i8(&mut self) -> Result<i8, CdrError> {
        Ok(i8::from_le_bytes(self.get()?))
    }

    pub(crate) fn u16(&mut self) -> Result<u16, CdrError> {
        Ok(u16::from_le_bytes(self.get()?))
    }

    pub(crate) fn i16(&mut self) -> Result<i16, CdrError> {
        Ok(i16::from_le_bytes(self.get()?))
    }

    pub(crate) fn u32(&mut self) -> Result<u32, CdrError> {
        Ok(u32::from_le_bytes(self.get()?))
    }

    pub(crate) fn i32(&mut self) -> Result<i32, CdrError> {
        Ok(i32::from_le_bytes(self.get()?))
    }

    pub(crate) fn u64(&mut self) -> Result<u64, CdrError> {
        Ok(u64::from_le_bytes(self.get()?))
    }

    pub(crate) fn i64(&mut self) -> Result<i64, CdrError> {
        Ok(i64::from_le_bytes(self.get()?))
    }

    pub(crate) fn f32(&mut self) -> Result<f32, CdrError> {
        Ok(f32::from_le_bytes(self.get()?))
    }

    pub(crate) fn f64(&mut self) -> Result<f64, CdrError> {
        Ok(f64::from_le_bytes(self.get()?))
    }

    pub(crate) fn char(&mut self) -> Result<char, CdrError> {
        let at = self.pos;
        let code = self.u32()?;
        char::from_u32(code).ok_or_else(|| invalid(at, format!("{code:#x} is not a character")))
    }

    pub(crate) fn str(&mut self) -> Result<&'de str, CdrError> {
        let at = self.pos;
        let len = self.u32()? as usize;
        if len == 0 {
            return Err(invalid(at, "a string without its terminating NUL".to_owned()));
        }
        let bytes = self.take(len)?;
        let (text, nul) = bytes.split_at(len - 1);
        if nul != [0] {
            return Err(invalid(at, "a string without its terminating NUL".to_owned()));
        }
        std::str::from_utf8(text)
            .map_err(|e| invalid(at, format!("a string that is not UTF-8: {e}")))
    }

    pub(crate) fn bytes(&mut self) -> Result<&'de [u8], CdrError> {
        let len = self.u32()? as usize;
        self.take(len)
    }

    /// A sequence's element count. Every element takes at least one byte but for values
    /// without data (units), so a count larger than what is left is damage, not data: it is
    /// refused before anything is allocated for it.
    pub(crate) fn count(&mut self) -> Result<usize, CdrError> {
        let at = self.pos;
        let count = self.u32()? as usize;
        if count > self.remaining() {
            return Err(invalid(
                at,
                format!("a count of {count} with {} bytes left", self.remaining()),
            ));
        }
        Ok(count)
    }

    /// An option's count: 0 or 1.
    pub(crate) fn option(&mut self) -> Result<bool, CdrError> {
        let at = self.pos;
        match self.u32()? {
            0 => Ok(false),
            1 => Ok(true),
            n => Err(invalid(at, format!("an optional value with {n} elements"))),
        }
    }
}

pub(crate) fn invalid(offset: usize, what: String) -> CdrError {
    CdrError::Invalid { offset, what }
}

impl<'de> de::Deserializer<'de> for &mut Reader<'de> {
    type Error = CdrError;

    fn is_human_readable(&self) -> bool {
        false
    }

    fn deserialize_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, CdrError> {
        Err(CdrError::NotSelfDescribing("a value read without a fixed type (deserialize_any)"))
    }

    fn deserialize_ignored_any<V: Visitor<'de>>(self, _: V) -> Result<V::Value, CdrError> {
        Err(CdrError::NotSelfDescribing("skipping a value"))
    }

    fn deserialize_identifier<V: Visitor<'de>>(self, _: V) -> Result<V::Value, CdrError> {
        Err(CdrError::NotSelfDescribing("a field name"))
    }

    fn deserialize_bool<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_bool(self.bool()?)
    }

    fn deserialize_i8<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_i8(self.i8()?)
    }

    fn deserialize_i16<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_i16(self.i16()?)
    }

    fn deserialize_i32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_i32(self.i32()?)
    }

    fn deserialize_i64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_i64(self.i64()?)
    }

    fn deserialize_u8<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_u8(self.u8()?)
    }

    fn deserialize_u16<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_u16(self.u16()?)
    }

    fn deserialize_u32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_u32(self.u32()?)
    }

    fn deserialize_u64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_u64(self.u64()?)
    }

    fn deserialize_f32<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_f32(self.f32()?)
    }

    fn deserialize_f64<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_f64(self.f64()?)
    }

    fn deserialize_char<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_char(self.char()?)
    }

    fn deserialize_str<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_borrowed_str(self.str()?)
    }

    fn deserialize_string<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_borrowed_str(self.str()?)
    }

    fn deserialize_bytes<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_borrowed_bytes(self.bytes()?)
    }

    fn deserialize_byte_buf<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_borrowed_bytes(self.bytes()?)
    }

    fn deserialize_option<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        if self.option()? { visitor.visit_some(self) } else { visitor.visit_none() }
    }

    fn deserialize_unit<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_unit()
    }

    fn deserialize_unit_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        visitor.visit_unit()
    }

    fn deserialize_newtype_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        visitor.visit_newtype_struct(self)
    }

    fn deserialize_seq<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        let count = self.count()?;
        visitor.visit_seq(Elements { reader: self, left: count })
    }

    fn deserialize_tuple<V: Visitor<'de>>(
        self,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        visitor.visit_seq(Elements { reader: self, left: len })
    }

    fn deserialize_tuple_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        len: usize,
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        visitor.visit_seq(Elements { reader: self, left: len })
    }

    fn deserialize_map<V: Visitor<'de>>(self, visitor: V) -> Result<V::Value, CdrError> {
        let count = self.count()?;
        visitor.visit_map(Elements { reader: self, left: count })
    }

    fn deserialize_struct<V: Visitor<'de>>(
        self,
        _: &'static str,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        visitor.visit_seq(Elements { reader: self, left: fields.len() })
    }

    fn deserialize_enum<V: Visitor<'de>>(
        self,
        _: &'static str,
        _: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        visitor.visit_enum(self)
    }
}

/// The elements of a sequence, tuple, struct or map, `left` of them still to read.
struct Elements<'r, 'de> {
    reader: &'r mut Reader<'de>,
    left: usize,
}

impl<'de> de::SeqAccess<'de> for Elements<'_, 'de> {
    type Error = CdrError;

    fn next_element_seed<T: DeserializeSeed<'de>>(
        &mut self,
        seed: T,
    ) -> Result<Option<T::Value>, CdrError> {
        if self.left == 0 {
            return Ok(None);
        }
        self.left -= 1;
        seed.deserialize(&mut *self.reader).map(Some)
    }

    fn size_hint(&self) -> Option<usize> {
        Some(self.left)
    }
}

impl<'de> de::MapAccess<'de> for Elements<'_, 'de> {
    type Error = CdrError;

    fn next_key_seed<K: DeserializeSeed<'de>>(
        &mut self,
        seed: K,
    ) -> Result<Option<K::Value>, CdrError> {
        if self.left == 0 {
            return Ok(None);
        }
        self.left -= 1;
        seed.deserialize(&mut *self.reader).map(Some)
    }

    fn next_value_seed<V: DeserializeSeed<'de>>(&mut self, seed: V) -> Result<V::Value, CdrError> {
        seed.deserialize(&mut *self.reader)
    }

    fn size_hint(&self) -> Option<usize> {
        Some(self.left)
    }
}

impl<'de> de::EnumAccess<'de> for &mut Reader<'de> {
    type Error = CdrError;
    type Variant = Self;

    fn variant_seed<V: DeserializeSeed<'de>>(self, seed: V) -> Result<(V::Value, Self), CdrError> {
        let index = self.u32()?;
        let variant = seed.deserialize(IntoDeserializer::<CdrError>::into_deserializer(index))?;
        Ok((variant, self))
    }
}

impl<'de> de::VariantAccess<'de> for &mut Reader<'de> {
    type Error = CdrError;

    fn unit_variant(self) -> Result<(), CdrError> {
        Ok(())
    }

    fn newtype_variant_seed<T: DeserializeSeed<'de>>(self, seed: T) -> Result<T::Value, CdrError> {
        seed.deserialize(self)
    }

    fn tuple_variant<V: Visitor<'de>>(self, len: usize, visitor: V) -> Result<V::Value, CdrError> {
        visitor.visit_seq(Elements { reader: self, left: len })
    }

    fn struct_variant<V: Visitor<'de>>(
        self,
        fields: &'static [&'static str],
        visitor: V,
    ) -> Result<V::Value, CdrError> {
        visitor.visit_seq(Elements { reader: self, left: fields.len() })
    }
}
