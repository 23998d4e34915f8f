//! JSON text exactly as orjson writes it (compact, keys in insertion order, non-ASCII kept as
//! UTF-8, control characters escaped).
//!
//! This is the hot path of `--format jsonl` (every record's strings pass through `push_str`),
//! so strings are scanned 8 bytes at a time and clean runs are copied at once, and integers
//! are formatted by `itoa` instead of `core::fmt`.

use crate::decoders::model::Value;
use crate::pyfloat::push_json_float;

const ONES: u64 = 0x0101_0101_0101_0101;
const HIGHS: u64 = 0x8080_8080_8080_8080;

/// True when one of the 8 bytes of `w` is a control character, `"` or `\` (the bytes orjson
/// escapes). Bytes >= 0x80 (UTF-8 of non-ASCII) never match.
#[inline]
fn needs_escape(w: u64) -> bool {
    // "has a byte < 0x20" and "has a zero byte after xor" (the classic bit tricks): exact as
    // booleans for these constants
    let lt20 = w.wrapping_sub(ONES * 0x20) & !w;
    let q = w ^ (ONES * u64::from(b'"'));
    let quote = q.wrapping_sub(ONES) & !q;
    let b = w ^ (ONES * u64::from(b'\\'));
    let bslash = b.wrapping_sub(ONES) & !b;
    (lt20 | quote | bslash) & HIGHS != 0
}

/// The escape of one byte, or None when it is written as it is.
#[inline]
fn escape(b: u8) -> Option<&'static str> {
    Some(match b {
        b'"' => "\\\"",
        b'\\' => "\\\\",
        b'\n' => "\\n",
        b'\r' => "\\r",
        b'\t' => "\\t",
        0x08 => "\\b",
        0x0c => "\\f",
        0..=0x1f => CONTROL[b as usize],
        _ => return None,
    })
}

/// `\u00XX` of the control characters without a short escape (orjson writes lowercase hex).
static CONTROL: [&str; 32] = [
    "\\u0000", "\\u0001", "\\u0002", "\\u0003", "\\u0004", "\\u0005", "\\u0006", "\\u0007",
    "\\u0008", "\\u0009", "\\u000a", "\\u000b", "\\u000c", "\\u000d", "\\u000e", "\\u000f",
    "\\u0010", "\\u0011", "\\u0012", "\\u0013", "\\u0014", "\\u0015", "\\u0016", "\\u0017",
    "\\u0018", "\\u0019", "\\u001a", "\\u001b", "\\u001c", "\\u001d", "\\u001e", "\\u001f",
];

/// True when `b` holds no byte that orjson escapes: the common case, checked a word at a time
/// (the last word overlaps the one before it instead of going byte by byte).
#[inline]
fn is_clean(b: &[u8]) -> bool {
    let word = |i: usize| u64::from_le_bytes(b[i..i + 8].try_into().expect("8 bytes"));
    let n = b.len();
    if n < 8 {
        return b.iter().all(|&c| CLEAN[c as usize]);
    }
    let mut i = 0;
    while i + 8 < n {
        if needs_escape(word(i)) {
            return false;
        }
        i += 8;
    }
    !needs_escape(word(n - 8))
}

/// A JSON string literal of `s`.
pub fn push_str(out: &mut String, s: &str) {
    out.reserve(s.len() + 2);
    out.push('"');
    if is_clean(s.as_bytes()) {
        out.push_str(s);
    } else {
        // the escaped bytes are ASCII, so every index where one is found is a char boundary
        let mut start = 0;
        for (i, &b) in s.as_bytes().iter().enumerate() {
            if let Some(e) = escape(b) {
                out.push_str(&s[start..i]);
                out.push_str(e);
                start = i + 1;
            }
        }
        out.push_str(&s[start..]);
    }
    out.push('"');
}

/// The bytes written as they are (everything but control characters, `"` and `\`).
static CLEAN: [bool; 256] = {
    let mut t = [true; 256];
    let mut b = 0;
    while b < 0x20 {
        t[b] = false;
        b += 1;
    }
    t[b'"' as usize] = false;
    t[b'\\' as usize] = false;
    t
};

/// Appends ASCII bytes (digits, hex digits, spaces) without `from_utf8`'s validation, which
/// cost more than the formatting itself.
#[inline]
pub fn push_ascii(out: &mut String, bytes: &[u8]) {
    if !bytes.is_ascii() {
        debug_assert!(false, "push_ascii of non-ASCII bytes");
        return; // never: the callers pass digits (the check keeps a misuse from breaking UTF-8)
    }
    // SAFETY: ASCII bytes are UTF-8 on their own, and `out` stays UTF-8 at char boundaries
    unsafe { out.as_mut_vec() }.extend_from_slice(bytes);
}

/// The decimal digits of `v` (as `{}` writes a u64).
#[inline]
pub fn push_u64(out: &mut String, v: u64) {
    out.push_str(itoa::Buffer::new().format(v));
}

/// The decimal digits of `v` (as `{}` writes an i64).
pub fn push_int(out: &mut String, v: i64) {
    if v < 0 {
        out.push('-');
    }
    push_u64(out, v.unsigned_abs());
}

pub fn push_value(out: &mut String, v: &Value) {
    match v {
        Value::Null => out.push_str("null"),
        Value::Bool(b) => out.push_str(if *b { "true" } else { "false" }),
        Value::Int(i) => push_int(out, *i),
        Value::Float(f) => push_json_float(out, *f),
        Value::Str(s) => push_str(out, s),
        Value::List(items) => {
            out.push('[');
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                push_value(out, item);
            }
            out.push(']');
        }
        Value::Map(entries) => push_map(out, entries),
    }
}

pub fn push_map(out: &mut String, entries: &[(crate::decoders::model::Str, Value)]) {
    out.push('{');
    for (i, (k, v)) in entries.iter().enumerate() {
        if i > 0 {
            out.push(',');
        }
        push_str(out, k);
        out.push(':');
        push_value(out, v);
    }
    out.push('}');
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn strings_as_orjson() {
        let mut s = String::new();
        push_str(&mut s, "a\u{b0}\n\u{1}\"\\ \u{2028}");
        assert_eq!(s, "\"a\u{b0}\\n\\u0001\\\"\\\\ \u{2028}\"");
    }

    /// The word-at-a-time scan against a plain per-byte escape, at every position and length.
    #[test]
    fn every_byte_at_every_position() {
        let reference = |s: &str| {
            let mut r = String::from("\"");
            for c in s.chars() {
                match c {
                    '"' => r.push_str("\\\""),
                    '\\' => r.push_str("\\\\"),
                    '\n' => r.push_str("\\n"),
                    '\r' => r.push_str("\\r"),
                    '\t' => r.push_str("\\t"),
                    '\u{8}' => r.push_str("\\b"),
                    '\u{c}' => r.push_str("\\f"),
                    c if (c as u32) < 0x20 => r.push_str(&format!("\\u{:04x}", c as u32)),
                    c => r.push(c),
                }
            }
            r.push('"');
            r
        };
        for len in 0..20 {
            for pos in 0..len.max(1) {
                for c in (0u32..0x80).chain([0xb0, 0x7ff, 0x2028, 0x1f600]) {
                    let mut s: String = "abcdefghijklmnopqrstu"[..len].into();
                    if len > 0 {
                        s.replace_range(pos..pos + 1, &char::from_u32(c).unwrap().to_string());
                    }
                    let mut got = String::new();
                    push_str(&mut got, &s);
                    assert_eq!(got, reference(&s), "{s:?}");
                }
            }
        }
    }

    #[test]
    fn integers_as_display() {
        let mut s = String::new();
        for v in [
            0,
            1,
            -1,
            9,
            10,
            99,
            100,
            101,
            12345,
            -987654321,
            i64::MIN,
            i64::MAX,
        ] {
            s.clear();
            push_int(&mut s, v);
            assert_eq!(s, v.to_string());
        }
        s.clear();
        push_u64(&mut s, u64::MAX);
        assert_eq!(s, u64::MAX.to_string());
        // every length, at its edges, appended after other text
        for k in 0..20u32 {
            let p = 10u64.pow(k);
            for v in [p - 1, p, p + 1, p.saturating_mul(7) / 3] {
                s.clear();
                s.push('x');
                push_u64(&mut s, v);
                assert_eq!(s, format!("x{v}"));
            }
        }
    }
}
