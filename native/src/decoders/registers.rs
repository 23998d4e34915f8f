//! The one register table of the EG2-4XX, shared by the Modbus RTU and CAN decoders.
//!
//! Mirrors `decoders/registers.py`. Modbus counts 16-bit registers (1001 ... 1065, or 1 ... 65
//! as some hosts send them, reference section 4); CAN counts bytes:
//! `CAN address = 1000 + 2 * (register - 1000)` (section 3.1). Run-state and fault-bit texts
//! (section 1.3) live here too: all three protocols use them.
//!
//! The table is a static array of `Register`s (written from the Python's by
//! `native/codegen.py`, in `generated.rs`); placeholders for registers the manual does not
//! describe are built on demand (their names are formatted), so lookups hand out
//! `Cow<'static, Register>`: borrowed from the table in the usual case.

use std::borrow::Cow;

use crate::decoders::model::Str;
use crate::generated::messages::value_out_of_range;
use crate::pyfloat::{push_py_repr, py_round};

pub use crate::generated::registers::{
    FAULT_BITS, FAULT_BIT_WORDS, FIRST, LAST, REGISTERS, SAVE_REGISTERS, STATE_TEXT, STROKE_MM,
};

pub fn is_save_register(number: i64) -> bool {
    SAVE_REGISTERS.contains(&number)
}

/// Opening 0-1000 to millimetres (linear; 1000 = 70 mm): `round(value * 70.0 / 1000.0, 2)`.
pub fn opening_mm(value: i64) -> f64 {
    py_round(value as f64 * STROKE_MM / 1000.0, 2)
}

/// The run state in words (`state_text`).
pub fn state_text(state: i64) -> Str {
    if (1..=6).contains(&state) {
        Cow::Borrowed(STATE_TEXT[(state - 1) as usize])
    } else {
        Cow::Owned(format!("unknown state {state}"))
    }
}

/// Fault bits in words; reserved bits 5-7 are named as such, bits 8-15 by number, higher
/// bits not at all (as the Python does).
pub fn fault_text(bits: i64) -> Vec<&'static str> {
    if bits == 0 {
        return Vec::new();
    }
    (0..16)
        .filter(|i| bits & (1 << i) != 0)
        .map(|i| FAULT_BIT_WORDS[i])
        .collect()
}

/// `", ".join(fault_text(bits)) or "no fault"`
pub fn fault_words(bits: i64) -> String {
    let words = fault_text(bits);
    if words.is_empty() {
        "no fault".to_string()
    } else {
        words.join(", ")
    }
}

/// One register of the map (Python `Register`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Register {
    /// Modbus register number, 1001 ... 1065
    pub number: i64,
    /// the manual's identifier
    pub name: Str,
    /// short snake_case name for device state and plots
    pub key: Str,
    /// "rw", "ro", or "?" for placeholders
    pub access: &'static str,
    /// documented range, None where the manual gives none
    pub lo: Option<i64>,
    pub hi: Option<i64>,
    pub unit: &'static str,
    pub signed: bool,
    pub meaning: Str,
    pub documented: bool,
}

impl Register {
    pub fn can_address(&self) -> i64 {
        1000 + 2 * (self.number - 1000)
    }

    /// A 16-bit wire value as this register's integer (two's complement if signed).
    pub fn value(&self, raw: i64) -> i64 {
        if self.signed && raw & 0x8000 != 0 {
            raw - 0x10000
        } else {
            raw
        }
    }

    pub fn in_range(&self, value: i64) -> bool {
        match (self.lo, self.hi) {
            (Some(lo), Some(hi)) => lo <= value && value <= hi,
            _ => true,
        }
    }

    /// `"{key} out of range ({lo}-{hi}): {value}"`, or None inside the range.
    pub fn range_warning(&self, value: i64) -> Option<String> {
        match (self.lo, self.hi) {
            (Some(lo), Some(hi)) if !(lo <= value && value <= hi) => {
                let (_, text) =
                    value_out_of_range!(label = self.key, lo = lo, hi = hi, value = value);
                Some(text)
            }
            _ => None,
        }
    }

    /// `target_opening=500 (35.0 mm)`, `temperature_c=37 °C`, `state=1 (fully open, idle)`.
    pub fn describe(&self, value: i64) -> String {
        let mut out = String::with_capacity(32);
        self.push_describe(&mut out, value);
        out
    }

    /// `describe`, appended to `out`.
    pub fn push_describe(&self, out: &mut String, value: i64) {
        use std::fmt::Write;
        let _ = write!(out, "{}={value}", self.key);
        if self.unit == "mm" {
            out.push_str(" (");
            push_py_repr(out, opening_mm(value));
            out.push_str(" mm)");
        } else if !self.unit.is_empty() {
            out.push(' ');
            out.push_str(self.unit);
        } else if self.key == "state" {
            out.push_str(" (");
            out.push_str(&state_text(value));
            out.push(')');
        } else if self.key == "fault" {
            out.push_str(" (");
            out.push_str(&fault_words(value));
            out.push(')');
        }
    }
}

/// A documented register of the table (all strings literals); one positional row per
/// register keeps the table as readable as the Python one.
#[allow(clippy::too_many_arguments)]
pub(crate) const fn reg(
    number: i64,
    name: &'static str,
    key: &'static str,
    access: &'static str,
    range: Option<(i64, i64)>,
    unit: &'static str,
    signed: bool,
    meaning: &'static str,
) -> Register {
    let (lo, hi) = match range {
        Some((lo, hi)) => (Some(lo), Some(hi)),
        None => (None, None),
    };
    Register {
        number,
        name: Cow::Borrowed(name),
        key: Cow::Borrowed(key),
        access,
        lo,
        hi,
        unit,
        signed,
        meaning: Cow::Borrowed(meaning),
        documented: true,
    }
}

/// A register, borrowed from the table or an owned placeholder.
pub type RegRef = Cow<'static, Register>;

/// BY_NUMBER
pub fn by_number(number: i64) -> Option<&'static Register> {
    REGISTERS
        .binary_search_by_key(&number, |r| r.number)
        .ok()
        .map(|i| &REGISTERS[i])
}

/// BY_NAME
pub fn by_name(name: &str) -> Option<&'static Register> {
    REGISTERS.iter().find(|r| r.name == name)
}

/// BY_KEY
pub fn by_key(key: &str) -> Option<&'static Register> {
    REGISTERS.iter().find(|r| r.key == key)
}

/// BY_CAN_ADDRESS: only the exact (even) address of a documented register.
pub fn by_can_address_exact(address: i64) -> Option<&'static Register> {
    if address % 2 != 0 {
        return None;
    }
    by_number(1000 + (address - 1000) / 2)
}

/// A placeholder for a register the manual does not describe (flagged): inside the map's span
/// by default, or anywhere else with its own `meaning` (Python `meaning or default`: an empty
/// meaning counts as none).
pub fn undocumented(number: i64, meaning: Option<Str>) -> Register {
    let meaning = match meaning {
        Some(m) if !m.is_empty() => m,
        _ => Cow::Owned(format!("undocumented register {number}")),
    };
    Register {
        number,
        name: Cow::Owned(format!("REG_{number}")),
        key: Cow::Owned(format!("reg_{number}")),
        access: "?",
        lo: None,
        hi: None,
        unit: "",
        signed: false,
        meaning,
        documented: false,
    }
}

/// Python `Lookup`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Lookup {
    pub register: RegRef,
    /// the host used the short numbering (10 for 1010, section 4)
    pub short: bool,
}

/// Resolve a Modbus register number in either numbering.
///
/// None outside the gripper's map (neither N nor 1000 + N falls in 1001-1065). Numbers inside
/// the span that the manual does not document resolve to a flagged placeholder register.
pub fn by_modbus(number: i64) -> Option<Lookup> {
    if let Some(reg) = by_number(number) {
        return Some(Lookup {
            register: Cow::Borrowed(reg),
            short: false,
        });
    }
    if (FIRST..=LAST).contains(&number) {
        return Some(Lookup {
            register: Cow::Owned(undocumented(number, None)),
            short: false,
        });
    }
    if (1..=LAST - 1000).contains(&number) {
        let full = number + 1000;
        let register = match by_number(full) {
            Some(reg) => Cow::Borrowed(reg),
            None => Cow::Owned(undocumented(full, None)),
        };
        return Some(Lookup {
            register,
            short: true,
        });
    }
    None
}

/// The register at a CAN byte address (even addresses 1002-1130), else None.
pub fn by_can_address(address: i64) -> Option<RegRef> {
    if let Some(reg) = by_can_address_exact(address) {
        return Some(Cow::Borrowed(reg));
    }
    if address % 2 == 0 && (1002..=1130).contains(&address) {
        return Some(Cow::Owned(undocumented(1000 + (address - 1000) / 2, None)));
    }
    None
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn table_sorted_and_addresses() {
        assert!(REGISTERS.windows(2).all(|w| w[0].number < w[1].number));
        assert_eq!(by_number(1010).unwrap().can_address(), 1020);
        assert_eq!(by_can_address(1020).unwrap().key, "target_opening");
        assert!(by_can_address(1021).is_none());
        assert!(by_can_address(1000).is_none());
        assert!(by_can_address(1132).is_none());
        let u = by_can_address(1016).unwrap();
        assert_eq!(
            (u.number, &*u.name, u.documented),
            (1008, "REG_1008", false)
        );
        assert_eq!(by_key("state").unwrap().number, 1065);
        assert_eq!(by_name("CMD_TEMP").unwrap().number, 1063);
    }

    #[test]
    fn modbus_numbering() {
        let l = by_modbus(10).unwrap();
        assert!(l.short && l.register.number == 1010);
        let l = by_modbus(8).unwrap();
        assert!(l.short && l.register.key == "reg_1008");
        assert!(!by_modbus(1008).unwrap().short);
        assert!(by_modbus(0).is_none());
        assert!(by_modbus(66).is_none());
        assert!(by_modbus(1066).is_none());
        let u = undocumented(5000, Some(Cow::Borrowed("")));
        assert_eq!(u.meaning, "undocumented register 5000");
    }

    #[test]
    fn texts() {
        let r = |n| by_number(n).unwrap();
        assert_eq!(r(1010).describe(500), "target_opening=500 (35.0 mm)");
        assert_eq!(r(1010).describe(1), "target_opening=1 (0.07 mm)");
        assert_eq!(r(1063).describe(37), "temperature_c=37 °C");
        assert_eq!(r(1065).describe(1), "state=1 (fully open, idle)");
        assert_eq!(r(1065).describe(9), "state=9 (unknown state 9)");
        assert_eq!(r(1064).describe(0), "fault=0 (no fault)");
        assert_eq!(
            r(1064).describe(0x121),
            "fault=289 (stall, reserved bit 5, bit 8)"
        );
        assert_eq!(r(1062).value(0xFFFF), -1);
        assert_eq!(r(1063).value(0xFFFF), 0xFFFF);
        assert_eq!(
            r(1011).range_warning(5).unwrap(),
            "speed out of range (10-1000): 5"
        );
        assert_eq!(r(1060).range_warning(99999), None);
        assert_eq!(opening_mm(333), 23.31);
    }
}
