//! The registers a Modbus (start, count) addresses, named once and memoised (mirrors
//! `decoders/modbus_registers.py`).
//!
//! Registers are named from `registers` in both numberings (1010, or 10 as some hosts send it;
//! the first register's numbering holds for a whole range). A `Plan` holds what every frame
//! over the same registers says (names, fields, numbering, undocumented or outside the map,
//! read-only); register values are memoised per (register, wire value) in `Cells`, so a
//! response with values already seen formats nothing.

use std::borrow::Cow;
use std::sync::Arc;
use std::sync::OnceLock;

use crate::decoders::model::{Fields, Notes, Str, Value};
use crate::decoders::registers::{
    by_modbus, by_number, is_save_register, RegRef, Register, FIRST, LAST,
};
use crate::generated::messages as M;

use crate::hash::FastMap;

/// The register at a full (1000-numbered) number; a placeholder where the map has none
/// (`_register`).
///
/// Placeholders are built here rather than by `registers::undocumented`: their name and key are
/// interned (below) so that the names a frame lists cost no allocation, and their `meaning`
/// (which no Modbus record shows) is left empty.
fn register(number: i64) -> RegRef {
    if let Some(reg) = by_number(number) {
        return Cow::Borrowed(reg);
    }
    let (name, key): (Str, Str) = match placeholder_names(number) {
        Some((name, key)) => (Cow::Borrowed(name), Cow::Borrowed(key)),
        None => (
            Cow::Owned(format!("REG_{number}")),
            Cow::Owned(format!("reg_{number}")),
        ),
    };
    Cow::Owned(Register {
        number,
        name,
        key,
        access: "?",
        lo: None,
        hi: None,
        unit: "",
        signed: false,
        meaning: Cow::Borrowed(""),
        documented: false,
    })
}

/// The highest register number whose placeholder names are interned: every number a frame can
/// list (a 16-bit start plus up to 126) is below it, so the interned names stay bounded
/// (~70,000 pairs, a few MB at most, only for numbers actually seen).
const INTERNED_MAX: i64 = 65_535 + 1_000 + 127;

/// `("REG_{n}", "reg_{n}")` for a placeholder register, made once per number and kept for the
/// life of the process (a field value must be a `&'static str` to be cloned without
/// allocating).
fn placeholder_names(number: i64) -> Option<(&'static str, &'static str)> {
    type Names = OnceLock<(&'static str, &'static str)>;
    // one slot per number (zeroed memory until a number is seen)
    static NAMES: [Names; INTERNED_MAX as usize + 1] =
        [const { OnceLock::new() }; INTERNED_MAX as usize + 1];
    let slot = NAMES.get(usize::try_from(number).ok()?)?;
    Some(*slot.get_or_init(|| {
        (
            Box::leak(format!("REG_{number}").into_boxed_str()),
            Box::leak(format!("reg_{number}").into_boxed_str()),
        )
    }))
}

fn outside(number: i64) -> bool {
    !(FIRST..=LAST).contains(&number)
}

/// 1013, 1014, 1015, 1018 -> "1013-1015, 1018".
pub fn spans(numbers: &[i64]) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut i = 0;
    while i < numbers.len() {
        let mut j = i;
        while j + 1 < numbers.len() && numbers[j + 1] == numbers[j] + 1 {
            j += 1;
        }
        parts.push(if i == j {
            numbers[i].to_string()
        } else {
            format!("{}-{}", numbers[i], numbers[j])
        });
        i = j + 1;
    }
    parts.join(", ")
}

/// What every frame over registers start .. start + count - 1 says about them: the short
/// numbering, undocumented registers, registers outside the map (regs: those a frame can
/// list).
fn map_notes(wire_start: i64, start: i64, count: i64, short: bool, regs: &[RegRef]) -> Notes {
    let mut notes = Notes::default();
    if short {
        if count <= 1 {
            notes.warn_of(M::modbus_short_number!(wire = wire_start, number = start));
        } else {
            notes.warn_of(M::modbus_short_numbers!(
                wire_first = wire_start,
                wire_last = wire_start + count - 1,
                first = start,
                last = start + count - 1
            ));
        }
    }
    let undoc: Vec<i64> = regs
        .iter()
        .filter(|r| !r.documented && !outside(r.number))
        .map(|r| r.number)
        .collect();
    if !undoc.is_empty() {
        let what = if undoc.len() == 1 {
            "register"
        } else {
            "registers"
        };
        notes.warn_of(M::modbus_undocumented_registers!(
            what = what,
            numbers = spans(&undoc)
        ));
    }
    // the numbers outside the map: those of the listed registers, then the unlisted ones up to
    // start + count; together, the numbers of [start, start + count) below FIRST or above LAST
    // (two runs, never adjacent: spans() of them, computed without listing up to 65535)
    let end = start + count;
    let runs = [(start, end.min(FIRST)), (start.max(LAST + 1), end)];
    let runs: Vec<(i64, i64)> = runs.into_iter().filter(|(a, b)| a < b).collect();
    let total: i64 = runs.iter().map(|(a, b)| b - a).sum();
    if total == 1 {
        notes.warn_of(M::modbus_outside_map!(number = runs[0].0));
    } else if total > 1 {
        let parts: Vec<String> = runs
            .iter()
            .map(|&(a, b)| {
                if b - a == 1 {
                    a.to_string()
                } else {
                    format!("{a}-{}", b - 1)
                }
            })
            .collect();
        notes.warn_of(M::modbus_outside_map_spans!(numbers = parts.join(", ")));
    }
    notes
}

/// The registers a (start, count) on the wire addresses, named once (Python `Plan`).
#[derive(Debug)]
pub struct Plan {
    /// the host used the short numbering (10 for 1010)
    pub short: bool,
    /// the full (1000-numbered) first register
    pub start: i64,
    pub count: i64,
    /// the fields every frame over these registers carries: start, count[, numbering, address]
    pub extra: Fields,
    /// the registers a frame can list (at most 127: the most a byte count can carry)
    pub regs: Vec<RegRef>,
    pub name: Option<Str>,
    pub summary_keys: String,
    /// what every frame over these registers says (numbering, undocumented, outside the map)
    pub warnings: Vec<String>,
    pub flags: Vec<&'static str>,
    /// "write to read-only register(s) ...", if any of them is
    pub read_only: Option<String>,
    /// indices into regs of the save registers (a write of 1 there makes the gripper pause)
    pub save_idx: Vec<usize>,
    /// a read request's `registers` field (the names of `regs`)
    pub names: Value,
    /// a read request's summary: "read {count} {noun} from {start} ({keys})"
    pub read_summary: String,
}

impl Plan {
    pub fn new(wire_start: i64, count: i64) -> Plan {
        // the numbering is the first register's (10 = 1010), as registers.by_modbus says
        let short = by_modbus(wire_start).is_some_and(|l| l.short);
        let start = if short { wire_start + 1000 } else { wire_start };
        let mut extra: Fields = vec![
            (Cow::Borrowed("start"), Value::Int(start)),
            (Cow::Borrowed("count"), Value::Int(count)),
        ];
        if short {
            extra.push((
                Cow::Borrowed("numbering"),
                Value::Str(Cow::Borrowed("short")),
            ));
            extra.push((Cow::Borrowed("address"), Value::Int(wire_start)));
        }
        let listed = count.min(127);
        let regs: Vec<RegRef> = (0..listed.max(0)).map(|i| register(start + i)).collect();
        let (name, summary_keys) = if count == 0 {
            (None, String::new())
        } else {
            let first = &regs[0];
            if count == 1 {
                (Some(first.name.clone()), first.key.to_string())
            } else {
                let last = register(start + count - 1);
                (
                    Some(Cow::Owned(format!("{}..{}", first.name, last.name))),
                    format!("{}..{}", first.key, last.key),
                )
            }
        };
        let notes = map_notes(wire_start, start, count, short, &regs);
        let read_only: Vec<String> = regs
            .iter()
            .filter(|r| r.access == "ro")
            .map(|r| format!("{} ({})", r.number, r.name))
            .collect();
        let read_only = if read_only.is_empty() {
            None
        } else {
            let what = if read_only.len() == 1 {
                "register"
            } else {
                "registers"
            };
            // modbus_read_only_write!'s text, made once per plan
            Some(M::modbus_read_only_write!(what = what, registers = read_only.join(", ")).1)
        };
        let names = Value::List(regs.iter().map(|r| Value::Str(r.name.clone())).collect());
        let noun = if count == 1 { "register" } else { "registers" };
        let mut read_summary = format!("read {count} {noun} from {start}");
        if !summary_keys.is_empty() {
            read_summary.push_str(&format!(" ({summary_keys})"));
        }
        let save_idx = (0..regs.len())
            .filter(|&i| is_save_register(regs[i].number))
            .collect();
        Plan {
            short,
            start,
            count,
            extra,
            regs,
            name,
            summary_keys,
            warnings: notes.warnings,
            flags: notes.flags,
            read_only,
            save_idx,
            names,
            read_summary,
        }
    }

    /// Add what every frame over these registers says to a frame's notes (`Plan.note`).
    pub fn note(&self, notes: &mut Notes) {
        notes.warnings.extend(self.warnings.iter().cloned());
        for code in &self.flags {
            notes.flag(code);
        }
    }
}

/// One register's wire value as (value, "key=value unit", range warning) (a Python cell entry).
#[derive(Debug)]
pub struct CellValue {
    /// the register number and wire value this entry is for (the cache's key)
    number: i64,
    raw: u16,
    pub value: i64,
    pub text: Box<str>,
    pub warning: Option<Box<str>>,
}

/// The memo tables of plans and register values (Python's module-level `_plans`/`_cells`;
/// pure caches: their contents never change what a frame says). Register values live in a
/// direct-mapped cache: a polling loop finds its values there without hashing or formatting.
pub struct Memo {
    plans: FastMap<(u16, u16), Arc<Plan>>,
    last_plan: Option<((u16, u16), Arc<Plan>)>,
    cells: Vec<Option<CellValue>>,
}

/// Plans kept at most (Python keeps 4096; a plan over 127 undocumented registers holds ~30 KB,
/// so fewer here keep memory flat under hostile input; the cache never changes the output).
const PLAN_LIMIT: usize = 256;
const CELL_SLOTS: usize = 1 << 13;

impl Default for Memo {
    fn default() -> Self {
        Memo {
            plans: FastMap::default(),
            last_plan: None,
            cells: (0..CELL_SLOTS).map(|_| None).collect(),
        }
    }
}

impl Memo {
    pub fn plan(&mut self, wire_start: u16, count: u16) -> Arc<Plan> {
        let key = (wire_start, count);
        if let Some((k, p)) = &self.last_plan {
            if *k == key {
                return p.clone();
            }
        }
        let p = if let Some(p) = self.plans.get(&key) {
            p.clone()
        } else {
            if self.plans.len() >= PLAN_LIMIT {
                self.plans.clear();
            }
            let p = Arc::new(Plan::new(wire_start as i64, count as i64));
            self.plans.insert(key, p.clone());
            p
        };
        self.last_plan = Some((key, p.clone()));
        p
    }

    /// (value, text, range warning) of a register's 16-bit wire value (`value_of`).
    pub fn value_of(&mut self, reg: &RegRef, raw: u16) -> &CellValue {
        let number = reg.number;
        let h = (number as u64)
            .wrapping_mul(0x9E37_79B9)
            .wrapping_add(raw as u64 * 0x85EB_CA6B);
        let slot = ((h ^ (h >> 13)) as usize) & (CELL_SLOTS - 1);
        let hit = matches!(&self.cells[slot], Some(c) if c.number == number && c.raw == raw);
        if !hit {
            let value = reg.value(raw as i64);
            self.cells[slot] = Some(CellValue {
                number,
                raw,
                value,
                text: reg.describe(value).into_boxed_str(),
                warning: reg.range_warning(value).map(String::into_boxed_str),
            });
        }
        self.cells[slot].as_ref().expect("just filled")
    }

    /// Values in raw[at..end] as {name: value}, their texts joined with ", " (appended to
    /// `texts`), their range warnings (`Plan.values`).
    pub fn values(
        &mut self,
        plan: &Plan,
        raw: &[u8],
        at: usize,
        end: usize,
        texts: &mut String,
        warns: &mut Vec<String>,
    ) -> Vec<(Str, Value)> {
        // zip(items, wire): as many as there are registers listed and whole words in the data
        let words = if end > at { (end - at) / 2 } else { 0 };
        let k = plan.regs.len().min(words);
        let mut values = Vec::with_capacity(k);
        for (i, reg) in plan.regs[..k].iter().enumerate() {
            let w = u16::from_be_bytes([raw[at + 2 * i], raw[at + 2 * i + 1]]);
            let c = self.value_of(reg, w);
            values.push((reg.name.clone(), Value::Int(c.value)));
            if i > 0 {
                texts.push_str(", ");
            }
            texts.push_str(&c.text);
            if let Some(warn) = &c.warning {
                warns.push(warn.to_string());
            }
        }
        values
    }
}

/// The 16-bit values (high byte first) in raw[lo..hi].
pub fn words(raw: &[u8], lo: usize, hi: usize) -> Vec<i64> {
    let mut out = Vec::new();
    let mut i = lo;
    while i + 1 < hi {
        out.push(((raw[i] as i64) << 8) | raw[i + 1] as i64);
        i += 2;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spans_text() {
        assert_eq!(spans(&[1013, 1014, 1015, 1018]), "1013-1015, 1018");
        assert_eq!(spans(&[5]), "5");
        assert_eq!(spans(&[]), "");
    }

    #[test]
    fn plan_short_and_undocumented() {
        let p = Plan::new(10, 3);
        assert!(p.short);
        assert_eq!(p.start, 1010);
        assert_eq!(p.name.as_deref(), Some("CMD_OPENLEN_SET..CMD_FORCE_SET"));
        assert_eq!(p.summary_keys, "target_opening..force");
        assert_eq!(
            p.warnings,
            vec![
                "short register numbers: 10-12 mean 1010-1012 (the host leaves out the 1000 \
                  offset, as some clients do)"
            ]
        );
        let p = Plan::new(1007, 5);
        assert_eq!(
            p.warnings,
            vec!["undocumented registers 1008-1009 (not in the manual's map)"]
        );
        let p = Plan::new(1064, 4);
        assert_eq!(
            p.warnings,
            vec!["registers 1066-1067 are outside the EG2 register map"]
        );
        assert_eq!(
            p.read_only.as_deref(),
            Some("write to read-only registers 1064 (CMD_ERRORCODE), 1065 (CMD_STATUS)")
        );
        let p = Plan::new(0, 0);
        assert!(p.name.is_none());
        assert_eq!(p.warnings, Vec::<String>::new());
    }

    /// The two runs of numbers outside the map say what listing them one by one would.
    #[test]
    fn outside_runs_match_a_listing() {
        for start in [0i64, 1, 990, 999, 1000, 1001, 1030, 1064, 1065, 1066, 5000] {
            for count in [0i64, 1, 2, 3, 66, 67, 127, 128, 200, 1000] {
                let regs: Vec<RegRef> = (0..count.min(127)).map(|i| register(start + i)).collect();
                let listed: Vec<i64> = (start..start + count).filter(|&n| outside(n)).collect();
                let want = match listed.len() {
                    0 => None,
                    1 => Some(format!(
                        "register {} is outside the EG2 register map",
                        listed[0]
                    )),
                    _ => Some(format!(
                        "registers {} are outside the EG2 register map",
                        spans(&listed)
                    )),
                };
                let notes = map_notes(start, start, count, false, &regs);
                let got = notes
                    .warnings
                    .iter()
                    .find(|w| w.contains("outside"))
                    .cloned();
                assert_eq!(got, want, "start {start} count {count}");
            }
        }
    }

    #[test]
    fn words_of() {
        assert_eq!(words(&[1, 2, 3, 4, 5], 0, 5), vec![0x0102, 0x0304]);
        assert_eq!(words(&[1, 2, 3], 2, 1), Vec::<i64>::new());
    }
}
