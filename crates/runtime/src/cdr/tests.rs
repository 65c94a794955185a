use std::collections::BTreeMap;

use proptest::prelude::*;
use serde::{Deserialize, Serialize};

use super::*;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
enum Goal {
    Idle,
    ObserveObject(String),
    GoTo { x: f64, y: f64 },
    Pair(u8, Option<i16>),
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
enum Category {
    Landmark,
    Mobile,
}

#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
struct Stamp(u64);

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Marker;

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
struct Sample {
    stamp: Stamp,
    flag: bool,
    small: i8,
    name: String,
    letter: char,
    covariance: [f64; 4],
    pair: (u32, String),
    goals: Vec<Goal>,
    category: Category,
    maybe: Option<f64>,
    nested: Option<Vec<Option<u16>>>,
    grid: Vec<Vec<i32>>,
    scores: BTreeMap<String, f32>,
    by_id: BTreeMap<u16, bool>,
    marker: Marker,
    unit: (),
    #[serde(with = "serde_bytes_like")]
    raw: Vec<u8>,
    last: i64,
}

/// Writes a `Vec<u8>` through `serialize_bytes`, as `serde_bytes` does.
mod serde_bytes_like {
    pub fn serialize<S: serde::Serializer>(v: &[u8], s: S) -> Result<S::Ok, S::Error> {
        s.serialize_bytes(v)
    }

    pub fn deserialize<'de, D: serde::Deserializer<'de>>(d: D) -> Result<Vec<u8>, D::Error> {
        struct Bytes;
        impl serde::de::Visitor<'_> for Bytes {
            type Value = Vec<u8>;
            fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str("bytes")
            }
            fn visit_bytes<E>(self, v: &[u8]) -> Result<Vec<u8>, E> {
                Ok(v.to_vec())
            }
        }
        d.deserialize_bytes(Bytes)
    }
}

fn sample() -> Sample {
    Sample {
        stamp: Stamp(1_234_567_890_123),
        flag: true,
        small: -3,
        name: "l_crossing#3".into(),
        letter: 'ß',
        covariance: [1e-300, -0.0, f64::MAX, 1.0 / 3.0],
        pair: (7, "seven".into()),
        goals: vec![
            Goal::Idle,
            Goal::ObserveObject("ball".into()),
            Goal::GoTo { x: 1.5, y: -2.0 },
            Goal::Pair(9, None),
            Goal::Pair(1, Some(-300)),
        ],
        category: Category::Mobile,
        maybe: Some(0.1 + 0.2),
        nested: Some(vec![Some(1), None, Some(65535)]),
        grid: vec![vec![1, -2], vec![], vec![i32::MIN]],
        scores: BTreeMap::from([("ball".to_owned(), 0.5), ("goal".to_owned(), -1.25)]),
        by_id: BTreeMap::from([(3, true), (700, false)]),
        marker: Marker,
        unit: (),
        raw: vec![0, 255, 7],
        last: i64::MIN,
    }
}

#[test]
fn values_round_trip_every_bit() {
    let mut bytes = Vec::new();
    encode(&sample(), &mut bytes).expect("encode");
    assert_eq!(bytes[..4], HEADER);
    let back: Sample = decode(&bytes).expect("decode");
    assert_eq!(back, sample());
    assert_eq!(back.covariance[1].to_bits(), (-0.0f64).to_bits());
}

#[test]
fn primitives_are_aligned_to_their_size_from_the_payload_start() {
    #[derive(Serialize)]
    struct Layout {
        a: u8,
        b: f64,
        c: u16,
        d: u32,
        e: String,
        f: Option<u8>,
    }
    let mut bytes = vec![0xee]; // something already in the buffer: alignment ignores it
    encode(&Layout { a: 1, b: 2.0, c: 3, d: 4, e: "ab".into(), f: Some(5) }, &mut bytes)
        .expect("encode");
    let mut expected = vec![0xee, 0, 1, 0, 0];
    expected.extend([1, 0, 0, 0, 0, 0, 0, 0]); // a, padding to 8
    expected.extend(2.0f64.to_le_bytes());
    expected.extend([3, 0, 0, 0]); // c, padding to 4
    expected.extend(4u32.to_le_bytes());
    expected.extend([3, 0, 0, 0, b'a', b'b', 0]); // length with NUL, text, NUL
    expected.extend([0, 1, 0, 0, 0, 5]); // padding to 4, count 1, value
    assert_eq!(bytes, expected);
}

#[test]
fn sequences_of_unknown_length_get_their_count_afterwards() {
    struct Unsized(Vec<u16>);
    impl Serialize for Unsized {
        fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
            s.collect_seq(self.0.iter().filter(|v| **v > 1))
        }
    }
    let mut bytes = Vec::new();
    encode(&Unsized(vec![1, 2, 3]), &mut bytes).expect("encode");
    assert_eq!(decode::<Vec<u16>>(&bytes).expect("decode"), vec![2, 3]);
}

#[test]
fn the_traced_format_reads_the_bytes_as_serde_json_writes_the_value() {
    let format = trace::<Sample>().expect("trace");
    let mut bytes = Vec::new();
    encode(&sample(), &mut bytes).expect("encode");
    let json = to_json(&format, &bytes).expect("to json");
    assert_eq!(json, serde_json::to_value(sample()).expect("serde_json"));
}

#[test]
fn tracing_finds_every_variant_and_shape() {
    let format = trace::<Sample>().expect("trace");
    let Format::Struct { name, fields } = &format else { panic!("{format:?}") };
    assert_eq!(name, "Sample");
    let field = |name: &str| &fields.iter().find(|f| f.name == name).expect(name).value;
    assert_eq!(
        *field("stamp"),
        Format::Newtype { name: "Stamp".into(), inner: Box::new(Format::U64) }
    );
    assert_eq!(*field("covariance"), Format::Array { element: Box::new(Format::F64), len: 4 });
    assert_eq!(*field("pair"), Format::Tuple(vec![Format::U32, Format::Str]));
    assert_eq!(*field("unit"), Format::Unit);
    assert_eq!(*field("raw"), Format::Bytes);
    let Format::Seq(goal) = field("goals") else { panic!() };
    let Format::Enum { variants, .. } = &**goal else { panic!() };
    let kinds: Vec<_> = variants.iter().map(|v| (v.name.as_str(), &v.value)).collect();
    assert_eq!(kinds[0], ("idle", &Variant::Unit));
    assert_eq!(kinds[1], ("observe_object", &Variant::Newtype(Format::Str)));
    assert!(matches!(kinds[2], ("go_to", Variant::Struct(f)) if f.len() == 2));
    assert_eq!(
        kinds[3],
        ("pair", &Variant::Tuple(vec![Format::U8, Format::Option(Box::new(Format::I16))]))
    );
}

#[test]
fn types_that_need_the_data_to_read_themselves_cannot_be_traced() {
    #[derive(Deserialize)]
    #[serde(tag = "kind")]
    #[allow(dead_code)]
    enum Tagged {
        A { x: f64 },
    }
    let error = trace::<Tagged>().expect_err("internally tagged");
    assert!(error.to_string().contains("deserialize_any"), "{error}");
    assert!(trace::<serde_json::Value>().is_err());
}

#[test]
fn a_field_left_out_when_serializing_is_an_error() {
    #[derive(Serialize)]
    struct Sparse {
        #[serde(skip_serializing_if = "Option::is_none")]
        x: Option<f64>,
    }
    let mut bytes = vec![1, 2];
    let error = encode(&Sparse { x: None }, &mut bytes).expect_err("skipped");
    assert_eq!(error, CdrError::SkippedField("x"));
    assert_eq!(bytes, [1, 2], "nothing of a failed value stays in the buffer");
    encode(&Sparse { x: Some(1.0) }, &mut bytes).expect("present");
}

#[test]
fn damaged_bytes_are_errors() {
    let mut bytes = Vec::new();
    encode(&sample(), &mut bytes).expect("encode");
    for cut in 0..bytes.len() {
        assert!(decode::<Sample>(&bytes[..cut]).is_err(), "cut at {cut}");
    }
    let mut longer = bytes.clone();
    longer.push(0);
    assert_eq!(decode::<Sample>(&longer), Err(CdrError::TrailingBytes(1)));
    let mut big_endian = bytes.clone();
    big_endian[1] = 0;
    assert!(matches!(decode::<Sample>(&big_endian), Err(CdrError::Header(_))));
    // A count far beyond the data is refused before anything is allocated for it.
    let huge = [0, 1, 0, 0, 0xff, 0xff, 0xff, 0xff];
    assert!(matches!(decode::<Vec<u64>>(&huge), Err(CdrError::Invalid { .. })));
    assert!(matches!(decode::<bool>(&[0, 1, 0, 0, 2]), Err(CdrError::Invalid { .. })));
    assert!(decode::<serde_json::Value>(&bytes).is_err());
}

#[test]
fn the_idl_schema_declares_every_type_before_it_is_used() {
    let schema = idl_schema(&trace::<Sample>().expect("trace"), "my::Sample").expect("idl");
    assert_eq!(schema.name, "strata::Sample");
    let text = &schema.text;
    for needed in [
        "module strata {",
        "struct Empty {};",
        "union Goal switch (unsigned long) {",
        "  case 0: Empty idle;",
        "  case 1: string observe_object;",
        "  case 2: Goal_go_to go_to;",
        "  double covariance[4];",
        "  sequence<Goal> goals;",
        "  sequence<Element_2, 1> nested;",
        "  sequence<Element_3> grid;",
        "struct Element_2 {\n  sequence<Element> value;\n};",
        "  sequence<Entry_2> by_id;",
        "  sequence<Entry> scores;",
        "  sequence<octet> raw;",
        "  unsigned long long stamp;",
        "  unsigned long letter;",
        "  Tuple pair;",
    ] {
        assert!(text.contains(needed), "missing `{needed}` in\n{text}");
    }
    let position = |needle: &str| text.find(needle).unwrap_or(usize::MAX);
    assert!(position("union Goal ") < position("struct Sample "));
    assert!(position("struct Goal_go_to ") < position("union Goal "));
}

#[test]
fn names_that_are_idl_keywords_are_escaped() {
    #[derive(Deserialize)]
    #[allow(dead_code)]
    struct Keywords {
        module: u8,
        r#struct: String,
    }
    let schema = idl_schema(&trace::<Keywords>().expect("trace"), "Keywords").expect("idl");
    assert!(schema.text.contains("octet _module;"), "{}", schema.text);
    assert!(schema.text.contains("string _struct;"), "{}", schema.text);
    let wrapped = idl_schema(&Format::U64, "core::u64").expect("idl");
    assert_eq!(wrapped.name, "strata::u64");
    assert!(wrapped.text.contains("struct u64 {\n  unsigned long long value;\n};"));
}

fn goal() -> impl Strategy<Value = Goal> {
    prop_oneof![
        Just(Goal::Idle),
        ".{0,12}".prop_map(Goal::ObserveObject),
        (any::<f64>(), any::<f64>()).prop_map(|(x, y)| Goal::GoTo { x, y }),
        (any::<u8>(), any::<Option<i16>>()).prop_map(|(a, b)| Goal::Pair(a, b)),
    ]
}

proptest! {
    #[test]
    fn any_value_round_trips_and_reads_as_json(
        goals in proptest::collection::vec(goal(), 0..6),
        name in ".{0,20}",
        maybe in any::<Option<f64>>(),
        nested in any::<Option<Vec<Option<u16>>>>(),
        raw in proptest::collection::vec(any::<u8>(), 0..9),
    ) {
        let value = Sample { goals, name, maybe, nested, raw, ..sample() };
        let mut bytes = Vec::new();
        encode(&value, &mut bytes).expect("encode");
        let back: Sample = decode(&bytes).expect("decode");
        // Bit for bit (NaN included): compare the encodings.
        let mut again = Vec::new();
        encode(&back, &mut again).expect("encode again");
        prop_assert_eq!(&again, &bytes);
        let json = to_json(&trace::<Sample>().expect("trace"), &bytes).expect("json");
        prop_assert_eq!(json, serde_json::to_value(&value).expect("serde_json"));
    }

    #[test]
    fn garbage_never_panics(bytes in proptest::collection::vec(any::<u8>(), 0..200)) {
        let mut framed = HEADER.to_vec();
        framed.extend(&bytes);
        let _ = decode::<Sample>(&framed);
        let _ = to_json(&trace::<Sample>().expect("trace"), &framed);
        let _ = decode::<Vec<Goal>>(&framed);
    }
}
