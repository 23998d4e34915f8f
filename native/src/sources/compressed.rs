//! A compressed capture that is cut short or damaged, in words: mirrors
//! analyzer/sources/compressed.py (the words are decoders/messages.py's, in generated.rs).

use crate::generated::messages as M;

/// gzip.BadGzipFile's words for a start that is no gzip
const NOT_GZIP: &str = "Not a gzipped file";

/// `compression_damage`: what the Python exception `kind: text` means: a file cut short,
/// damaged data, or data that is no gzip at all (`at_start`: nothing was read before it);
/// None for any other error. `after` says where (" after N bytes").
pub fn compression_damage(kind: &str, text: &str, at_start: bool, after: &str) -> Option<String> {
    match kind {
        "EOFError" => Some(format!(
            "{}{after}; {}",
            M::CAPTURE_GZIP_CUT,
            M::CAPTURE_REST_LOST
        )),
        "BadGzipFile" if at_start && text.starts_with(NOT_GZIP) => {
            Some(M::CAPTURE_NOT_GZIP.to_string())
        }
        // zlib.error's name is "error"
        "BadGzipFile" | "error" => Some(format!(
            "{}{after} ({text}); {}",
            M::CAPTURE_GZIP_DAMAGED,
            M::CAPTURE_REST_LOST
        )),
        _ => None,
    }
}
