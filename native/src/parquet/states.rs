//! State samples as Arrow columns, for the fleet dataset's `states/` table
//! (analyzer/fleet/tables.py): the Tracker's samples (tracker.rs) of a decode, with no Python
//! object per sample.
//!
//! As for the records (records.rs), Python describes the columns at the start (their names and
//! types, from analyzer/fleet/tables.py `STATE_COLUMNS`, one home for them); these builders
//! fill them in that order. A column is a sample's `bus`, `t`, `device`, `protocol` or `seq`, a
//! state value by its `VALUE_KEYS` name, or `changed` (the names of the fields the record set).
//! Each value goes in as `pa.array(values, type)` takes the Python values of a `StateSample`
//! (floats as they are, NaN included); a value of another type is an error (one `pa.array`
//! refuses too, a bool for an int; the decoders give none).

use crate::parquet::records::{is_str_list, Buffers, Column, ColumnSpec, Type};
use crate::session::tracker::{Changed, Sample, Slot, Values, SLOTS, VALUE_KEYS};

/// What a column holds.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Field {
    Bus,
    T,
    Device,
    Protocol,
    Seq,
    /// `VALUE_KEYS[i]`: a slot (`i < SLOTS`) or a counter
    Value(usize),
    Changed,
}

impl Field {
    /// The field of a column name, with the type its column must have (None: a value column,
    /// whose type the description chooses).
    fn by_name(name: &str) -> Option<(Field, Option<Type>)> {
        Some(match name {
            "bus" => (Field::Bus, Some(Type::Str)),
            "t" => (Field::T, Some(Type::Float)),
            "device" => (Field::Device, Some(Type::Int)),
            "protocol" => (Field::Protocol, Some(Type::Str)),
            "seq" => (Field::Seq, Some(Type::Int)),
            "changed" => (Field::Changed, Some(Type::List)),
            _ => {
                let i = VALUE_KEYS.iter().position(|k| *k == name)?;
                let counter = (i >= SLOTS).then_some(Type::Int);
                (Field::Value(i), counter)
            }
        })
    }
}

/// A state sample's parts: its record's time, bus and seq, its gripper's state after it.
pub struct Row<'a> {
    pub t: Option<f64>,
    pub bus: &'a str,
    pub device: i64,
    pub protocol: &'static str,
    pub seq: i64,
    pub values: &'a Values,
    pub changed: Changed,
}

/// A batch of state samples as columns.
pub struct StateColumns {
    columns: Vec<(Field, Column)>,
    rows: usize,
}

impl StateColumns {
    /// Builders for the columns `specs` describes (top level only: `changed` is a list of
    /// strings, every other column a plain int64, float64 or string); an error for a column
    /// these builders cannot fill.
    pub fn new(specs: &[ColumnSpec]) -> Result<StateColumns, String> {
        let mut columns = Vec::new();
        let mut at = 0;
        while at < specs.len() {
            let spec = &specs[at];
            let (field, ty) = Field::by_name(&spec.name)
                .ok_or_else(|| format!("no state value for column {}", spec.name))?;
            let plain = matches!(spec.ty, Type::Int | Type::Float | Type::Str);
            if ty.is_some_and(|ty| ty != spec.ty) || (ty.is_none() && !plain) {
                return Err(format!(
                    "state column {} cannot be {:?}",
                    spec.name, spec.ty
                ));
            }
            let column = Column::build(specs, &mut at)?;
            if field == Field::Changed && !is_str_list(&column) {
                return Err("state column changed is not a list of strings".into());
            }
            columns.push((field, column));
        }
        Ok(StateColumns { columns, rows: 0 })
    }

    /// Rows held.
    pub fn rows(&self) -> usize {
        self.rows
    }

    /// One sample as one row; an error (naming the column) for a value its column's type does
    /// not take. A row that fails is not held.
    pub fn push(&mut self, s: &Sample) -> Result<(), String> {
        let row = Row {
            t: s.t,
            bus: &s.bus,
            device: s.device,
            protocol: s.protocol,
            seq: s.seq,
            values: &s.values,
            changed: s.changed,
        };
        self.push_row(&row)
    }

    /// `push` of a sample's parts (a Tracker's state, as `Tracker::update_with` gives it).
    pub fn push_row(&mut self, s: &Row<'_>) -> Result<(), String> {
        for (field, col) in &self.columns {
            if let Field::Value(i) = *field {
                if i < SLOTS && !fits(&s.values.slots[i], col.ty) {
                    let value = &s.values.slots[i];
                    return Err(format!(
                        "state value {} = {value:?} does not fit its column ({:?})",
                        VALUE_KEYS[i], col.ty
                    ));
                }
            }
        }
        for (field, col) in &mut self.columns {
            match *field {
                Field::Bus => col.push_str(s.bus),
                Field::T => match s.t {
                    Some(t) => col.push_raw_float(t),
                    None => col.push_null(),
                },
                Field::Device => col.push_int(s.device),
                Field::Protocol => col.push_str(s.protocol),
                Field::Seq => col.push_int(s.seq),
                Field::Value(i) if i < SLOTS => push_slot(col, &s.values.slots[i]),
                Field::Value(i) => col.push_int(match i - SLOTS {
                    0 => s.values.frames,
                    1 => s.values.errors,
                    _ => s.values.unanswered,
                }),
                Field::Changed => col.push_strs(s.changed.iter().map(|f| VALUE_KEYS[f])),
            }
        }
        self.rows += 1;
        Ok(())
    }

    /// Hand out the rows held, column by column (depth first, in the order of the
    /// description), and start a new batch.
    pub fn take(&mut self, out: &mut dyn FnMut(Buffers<'_>)) {
        let rows = self.rows;
        for (_, col) in &mut self.columns {
            col.take(rows, out);
        }
        self.rows = 0;
    }
}

/// Whether `pa.array` takes the slot's Python value into a column of type `ty` (None always;
/// an int into a float column too; a bool is no int there).
fn fits(slot: &Slot, ty: Type) -> bool {
    matches!(
        (slot, ty),
        (Slot::Null, _)
            | (Slot::Int(_), Type::Int | Type::Float)
            | (Slot::Float(_), Type::Float)
            | (Slot::Text(_), Type::Str)
    )
}

fn push_slot(col: &mut Column, slot: &Slot) {
    match (slot, col.ty) {
        (Slot::Int(i), Type::Float) => col.push_raw_float(*i as f64),
        (Slot::Int(i), _) => col.push_int(*i),
        (Slot::Float(f), _) => col.push_raw_float(*f),
        (Slot::Text(s), _) => col.push_str(s),
        _ => col.push_null(), // Null (`fits` let nothing else through)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    fn columns() -> StateColumns {
        let specs = [
            ColumnSpec::new("bus", Type::Str, 0),
            ColumnSpec::new("t", Type::Float, 0),
            ColumnSpec::new("opening", Type::Int, 0),
            ColumnSpec::new("latency_ms", Type::Float, 0),
            ColumnSpec::new("last_command", Type::Str, 0),
            ColumnSpec::new("frames", Type::Int, 0),
            ColumnSpec::new("changed", Type::List, 1),
            ColumnSpec::new("item", Type::Str, 0),
        ];
        StateColumns::new(&specs).unwrap()
    }

    fn sample(opening: Slot) -> Sample {
        let mut values = Values::default();
        values.slots[crate::session::tracker::OPENING] = opening;
        values.frames = 3;
        let mut changed = Changed::default();
        changed.add(crate::session::tracker::OPENING);
        Sample {
            t: Some(f64::NAN),
            bus: Arc::from("can0"),
            device: 1,
            protocol: "eg2-can",
            seq: 7,
            changed,
            values,
        }
    }

    fn taken(cols: &mut StateColumns) -> Vec<Buffers<'static>> {
        let mut out = Vec::new();
        cols.take(&mut |b| {
            out.push(match b {
                Buffers::AllNull(n) => Buffers::AllNull(n),
                Buffers::Data { len, nulls, .. } => Buffers::Data {
                    len,
                    nulls,
                    validity: None,
                    values: &[],
                    bytes: None,
                },
            })
        });
        out
    }

    #[test]
    fn samples_fill_their_columns_and_nan_is_kept() {
        let mut cols = columns();
        cols.push(&sample(Slot::Int(500))).unwrap();
        cols.push(&sample(Slot::Null)).unwrap();
        assert_eq!(cols.rows(), 2);
        let out = taken(&mut cols);
        let lens: Vec<_> = out
            .iter()
            .map(|b| match b {
                Buffers::AllNull(n) => (*n, *n),
                Buffers::Data { len, nulls, .. } => (*len, *nulls),
            })
            .collect();
        // bus, t (NaN is a value), opening (one null), latency and last_command (all null),
        // frames, changed, its items
        assert_eq!(
            lens,
            vec![
                (2, 0),
                (2, 0),
                (2, 1),
                (2, 2),
                (2, 2),
                (2, 0),
                (2, 0),
                (2, 0)
            ]
        );
        assert_eq!(cols.rows(), 0);
    }

    #[test]
    fn a_value_its_column_does_not_take_is_an_error() {
        let mut cols = columns();
        let err = cols.push(&sample(Slot::Bool(true))).unwrap_err();
        assert!(err.contains("opening"), "{err}");
        assert_eq!(cols.rows(), 0);
        cols.push(&sample(Slot::Int(1))).unwrap();
        assert_eq!(cols.rows(), 1);
    }

    #[test]
    fn a_description_the_builders_cannot_fill_is_refused() {
        for specs in [
            vec![ColumnSpec::new("nope", Type::Int, 0)],
            vec![ColumnSpec::new("t", Type::Int, 0)],
            vec![ColumnSpec::new("frames", Type::Float, 0)],
        ] {
            assert!(StateColumns::new(&specs).is_err());
        }
    }
}
