//! Protocol names and detection for byte streams: decoders/registry.py (`ALIASES`,
//! `resolve_protocol`, `detect_protocol`).
//!
//! Detection decodes the sample with each byte-stream decoder, as the Python does, and takes
//! the one that finds the most valid frames: the two decoders are the reference for what a
//! frame is, so no second, cheaper opinion could agree with them on every input.

use crate::decoders::eg2_serial::Eg2SerialDecoder;
use crate::decoders::framing::StreamDecoder;
use crate::decoders::modbus_rtu::ModbusRtuDecoder;
use crate::decoders::model::{Record, EG2_SERIAL, MODBUS_RTU};
use std::sync::Arc;

pub use crate::generated::registry::ALIASES;

/// registry.py `resolve_protocol`: the canonical name of a protocol name or alias (any case),
/// or the Python ValueError's text listing the choices.
pub fn resolve_protocol(name: &str) -> Result<&'static str, String> {
    let lower = name.to_lowercase();
    if let Some((_, canonical)) = ALIASES.iter().find(|(alias, _)| *alias == lower) {
        return Ok(canonical);
    }
    let mut choices: Vec<&str> = ALIASES.iter().map(|(alias, _)| *alias).collect();
    choices.sort_unstable();
    Err(format!(
        "unknown protocol {}; choose one of: {}",
        py_str_repr(name),
        choices.join(", ")
    ))
}

/// Python's `repr(s)` of a str, for the message above (quotes as Python picks them).
fn py_str_repr(s: &str) -> String {
    let quote = if s.contains('\'') && !s.contains('"') {
        '"'
    } else {
        '\''
    };
    let mut out = String::new();
    out.push(quote);
    for c in s.chars() {
        match c {
            '\\' => out.push_str("\\\\"),
            '\n' => out.push_str("\\n"),
            '\r' => out.push_str("\\r"),
            '\t' => out.push_str("\\t"),
            c if c == quote => {
                out.push('\\');
                out.push(c);
            }
            c if (c as u32) < 0x20 || c as u32 == 0x7f => {
                out.push_str(&format!("\\x{:02x}", c as u32));
            }
            // Python also escapes non-printable non-ASCII (str.isprintable); rare in a
            // protocol name typed on a command line
            c => out.push(c),
        }
    }
    out.push(quote);
    out
}

/// Valid frames (`Record.ok`) the decoder finds in `sample` fed as one chunk, then finished.
fn count_ok(dec: &mut dyn StreamDecoder, sample: &[u8]) -> usize {
    let mut records: Vec<Record> = Vec::new();
    dec.feed(sample, None, &mut records);
    dec.finish(&mut records);
    records.iter().filter(|r| r.ok()).count()
}

/// registry.py `detect_protocol`: which byte-stream protocol a sample of a line holds: the one
/// that finds the most valid frames in it (None if neither finds any; on a tie the first of
/// serial, Modbus).
pub fn detect_protocol(sample: &[u8]) -> Option<&'static str> {
    let mut best = None;
    let mut best_count = 0;
    // in the order of registry.py STREAM_DECODERS, each with its default bus name
    let candidates: [(&'static str, Box<dyn StreamDecoder>); 2] = [
        (
            EG2_SERIAL,
            Box::new(Eg2SerialDecoder::new(Arc::from("serial"))),
        ),
        (
            MODBUS_RTU,
            Box::new(ModbusRtuDecoder::new(Arc::from("rs485"))),
        ),
    ];
    for (name, mut dec) in candidates {
        let count = count_ok(dec.as_mut(), sample);
        if count > best_count {
            best = Some(name);
            best_count = count;
        }
    }
    best
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn aliases() {
        assert_eq!(resolve_protocol("RS485"), Ok(MODBUS_RTU));
        assert_eq!(
            resolve_protocol("x'y").unwrap_err(),
            "unknown protocol \"x'y\"; choose one of: can, eg2-can, eg2-serial, modbus, \
             modbus-rtu, rs232, rs485, serial"
        );
    }

    #[test]
    fn nothing_valid_is_none() {
        assert_eq!(detect_protocol(b""), None);
        assert_eq!(detect_protocol(&[0u8; 100]), None);
    }

    #[test]
    fn a_serial_frame() {
        // EB 90, id 1, len 1, cmd 0x41 (read run state), checksum
        let f = [0xEB, 0x90, 0x01, 0x01, 0x41, 0x43];
        assert_eq!(detect_protocol(&f), Some(EG2_SERIAL));
    }
}
