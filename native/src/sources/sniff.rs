//! What a capture file holds, told from its first bytes whatever its name: analyzer/sources/
//! sniff.py, so that both engines choose the same reader. Binary formats by their magic (MCAP,
//! BLF `LOGG`, MF4 `MDF`), text logs by their first line that is not blank or a comment.

use std::path::Path;

use crate::decoders::registry::detect_protocol;
use crate::sources::candump::{first_bytes, parses_as_candump, BOM, HEAD_SIZE};

/// sniff.py `LINES`: lines looked at for the first significant one.
const LINES: usize = 32;

/// sniff.py `MAGIC`, in its order.
const MAGIC: [(&[u8], &str); 4] = [
    (b"\x89MCAP0\r\n", "mcap"),
    (b"LOGG", "blf"),
    (b"MDF     ", "mf4"),
    (b"UnFinMF ", "mf4"),
];
/// sniff.py `ASC_STARTS`, `CSV_START`, `TRC_VERSION`
const ASC_STARTS: [&[u8]; 5] = [
    b"date ",
    b"base ",
    b"begin triggerblock",
    b"internal events logged",
    b"no internal events logged",
];
const CSV_START: &[u8] = b"timestamp,arbitration_id,";
const TRC_VERSION: &[u8] = b";$FILEVERSION";

/// sniff.py `BINARY`: a C0 control byte no text log holds (all but tab, line feed, vertical
/// tab, form feed, carriage return and escape) makes the head a raw byte dump
fn binary(b: u8) -> bool {
    b < 0x20 && !matches!(b, 0x09..=0x0D | 0x1B)
}

/// Python's `bytes.isspace` characters (`bytes.strip()`).
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\n' | b'\r' | 0x0b | 0x0c)
}

fn strip(s: &[u8]) -> &[u8] {
    let lo = s.iter().position(|&b| !is_space(b)).unwrap_or(s.len());
    let hi = s.iter().rposition(|&b| !is_space(b)).map_or(lo, |i| i + 1);
    &s[lo..hi]
}

fn isdigit(s: &[u8]) -> bool {
    !s.is_empty() && s.iter().all(u8::is_ascii_digit)
}

/// sniff.py `sniff`: "mcap", "blf", "mf4", "candump", "trc", "asc", "csv", or None.
pub fn sniff(path: &Path) -> Option<&'static str> {
    sniff_head(&first_bytes(path))
}

/// sniff.py `sniff_head`
pub fn sniff_head(data: &[u8]) -> Option<&'static str> {
    if let Some((_, fmt)) = MAGIC.iter().find(|(magic, _)| data.starts_with(magic)) {
        return Some(fmt);
    }
    if data.iter().any(|&b| binary(b)) && detect_protocol(data).is_some() {
        return Some("bytes");
    }
    let full = data.len() >= HEAD_SIZE;
    let data = data.strip_prefix(BOM).unwrap_or(data);
    let sep = if data.contains(&b'\n') || !data.contains(&b'\r') {
        b'\n'
    } else {
        b'\r'
    };
    let mut lines: Vec<&[u8]> = data.split(|&b| b == sep).collect();
    if full {
        lines.pop(); // the head may end inside a line
    }
    let mut commented = false; // ";" comments: a PCAN trace's header
    for line in lines.into_iter().take(LINES) {
        let text = strip(line);
        if text.is_empty() || text.starts_with(b"//") {
            continue;
        }
        if text[0] == b';' {
            if text.to_ascii_uppercase().starts_with(TRC_VERSION) {
                return Some("trc");
            }
            commented = true;
            continue;
        }
        let lower = text.to_ascii_lowercase();
        if ASC_STARTS.iter().any(|s| lower.starts_with(s)) {
            return Some("asc");
        }
        if lower.starts_with(CSV_START) {
            return Some("csv");
        }
        if text[0] == b'#' {
            continue;
        }
        return frame_line(text, commented);
    }
    None
}

/// sniff.py `_frame_line`: the format of a log's first frame line.
fn frame_line(text: &[u8], commented: bool) -> Option<&'static str> {
    if parses_as_candump(text) {
        return Some("candump");
    }
    let first = text
        .split(|&b| is_space(b))
        .find(|p| !p.is_empty())
        .unwrap_or_default();
    if first.last() == Some(&b')') && isdigit(&first[..first.len() - 1]) {
        return Some("trc"); // a PCAN trace 1.x message number "12)"
    }
    if commented && isdigit(first) {
        return Some("trc"); // 2.x: "12" after the ";" header
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn formats_by_content() {
        assert_eq!(sniff_head(b"LOGG\x90\0\0\0"), Some("blf"));
        assert_eq!(sniff_head(b"(1.0) can0 123#11\n"), Some("candump"));
        assert_eq!(sniff_head(b"\n  can0  123   [1]  11\n"), Some("candump"));
        assert_eq!(
            sniff_head(b"# x\n(2020-12-19 12:04:45.1) can0 ERROR\n"),
            Some("candump")
        );
        assert_eq!(sniff_head(b";$FILEVERSION=2.1\n"), Some("trc"));
        assert_eq!(sniff_head(b";x\n  1) 17 0100 0\n"), Some("trc"));
        assert_eq!(sniff_head(b";x\n 1  17.1 DT 0100 Rx 0\n"), Some("trc"));
        assert_eq!(sniff_head(b"date Mon Jan 1\r\n"), Some("asc"));
        assert_eq!(
            sniff_head(b"timestamp,arbitration_id,extended\n"),
            Some("csv")
        );
        assert_eq!(sniff_head(b"\xeb\x90\x01\x01\x41\x43"), Some("bytes"));
        assert_eq!(sniff_head(b"\x1b[1mcolour\x1b[0m\n"), None);
        assert_eq!(sniff_head(b""), None);
    }
}
