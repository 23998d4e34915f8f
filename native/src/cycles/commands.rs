//! analyzer/cycles/commands.py: the commands that start and stop a gripper's motion, and their
//! answers, found in the native records (`command_of`, `answer_of`). The Python is the
//! reference (its text says which records count); tests/native/test_cycles_native.py and the
//! byte-session tests require the same cycles on both engines.

use super::rules::Command;
use super::segmenter::{Event, Key};
use crate::decoders::model::{Record, Value, EG2_CAN, EG2_SERIAL, MODBUS_RTU, REQUEST, RESPONSE};
use crate::decoders::registers::opening_mm;
use crate::generated::cycles::{
    ANSWERED, CAN_WRITE, CODES, MODBUS_WRITES, MOVE, NOBODY, NOT_ANSWERED, SERIAL_COMMANDS, STOP,
    STOPPED_FIRST, STOP_REGISTER, TARGET, WORDS,
};
use crate::generated::flags::{
    CUT_OFF, EXCEPTION_RESPONSE, RETRANSMISSION, UNANSWERED, WRITE_FAILED,
};
use crate::generated::{can, modbus, serial};
use crate::pyfloat::push_py_repr;
use std::fmt::Write;
use std::sync::Arc;

/// What a cycle keeps of its command beyond the rules' part: where it was and its words.
#[derive(Debug)]
pub struct Said {
    pub bus: Arc<str>,
    pub words: String,
}

/// The command or the answer `rec` is, if any (`command_of(rec) or answer_of(rec)`), with
/// the gripper it is for.
pub fn event_of(rec: &Record) -> Option<(Key, Event<Arc<Said>>)> {
    if !rec.code.is_some_and(|c| CODES.contains(&c)) {
        return None; // the protocols share numbers: a candidate is checked again below
    }
    let device = rec.device?;
    let key = || (rec.bus.clone(), device);
    if rec.direction == Some(RESPONSE) {
        let request = rec.pair?;
        let refused = rec.flags.contains(&WRITE_FAILED) || rec.flags.contains(&EXCEPTION_RESPONSE);
        let garbled = !rec.errors.is_empty();
        let (seq, t) = (rec.seq, rec.t);
        return Some((
            key(),
            Event::Answer {
                seq,
                t,
                request,
                refused,
                garbled,
            },
        ));
    }
    if rec.direction != Some(REQUEST) || !rec.errors.is_empty() {
        return None;
    }
    let (kind, target, words) = match rec.protocol {
        EG2_SERIAL => serial_command(rec)?,
        MODBUS_RTU if rec.code.is_some_and(|c| MODBUS_WRITES.contains(&c)) => registers(rec)?,
        EG2_CAN if rec.code == Some(CAN_WRITE) => registers(rec)?,
        _ => return None,
    };
    let broadcast = device == broadcast_of(rec.protocol)?;
    let fate = if broadcast { NOBODY } else { fate(rec) };
    let command = Command {
        seq: rec.seq,
        t: rec.t,
        kind: kind.to_owned(),
        target,
        fate: fate.to_owned(),
        broadcast,
        retransmission: rec.flags.contains(&RETRANSMISSION),
        same: rec.raw.clone(),
        payload: Arc::new(Said {
            bus: rec.bus.clone(),
            words,
        }),
    };
    Some((key(), Event::Command(command)))
}

/// `_BROADCAST`: the device every gripper of a bus executes.
fn broadcast_of(protocol: &str) -> Option<i64> {
    match protocol {
        EG2_SERIAL => Some(i64::from(serial::BROADCAST)),
        MODBUS_RTU => Some(i64::from(modbus::BROADCAST)),
        EG2_CAN => Some(i64::from(can::BROADCAST)),
        _ => None,
    }
}

/// `_fate`: how pairing left the request.
fn fate(rec: &Record) -> &'static str {
    if rec.pair.is_some() {
        ANSWERED
    } else if rec.flags.contains(&UNANSWERED) {
        NOT_ANSWERED
    } else if rec.flags.contains(&CUT_OFF) {
        STOPPED_FIRST
    } else {
        ANSWERED
    }
}

fn field<'a>(fields: &'a [(crate::decoders::model::Str, Value)], key: &str) -> Option<&'a Value> {
    fields.iter().find(|(k, _)| k == key).map(|(_, v)| v)
}

/// `isinstance(value, int)` (a bool is one).
fn int_of(value: Option<&Value>) -> Option<i64> {
    match value? {
        Value::Int(v) => Some(*v),
        Value::Bool(b) => Some(i64::from(*b)),
        _ => None,
    }
}

/// `_serial`: a catch, release, seek (with its position) or stop.
fn serial_command(rec: &Record) -> Option<(&'static str, Option<i64>, String)> {
    let code = rec.code?;
    let &(_, kind) = SERIAL_COMMANDS
        .iter()
        .find(|(c, _)| i64::from(*c) == code)?;
    let target = if kind == MOVE {
        Some(int_of(field(&rec.fields, "position"))?) // a seek without its position: none
    } else {
        None
    };
    Some((kind, target, rec.summary.to_string()))
}

/// `_registers`: a write of the target opening (a move) or of 1 to the stop register.
fn registers(rec: &Record) -> Option<(&'static str, Option<i64>, String)> {
    let single;
    let values: &[(crate::decoders::model::Str, Value)] = match field(&rec.fields, "values") {
        Some(Value::Map(values)) => values,
        _ => match (field(&rec.fields, "name"), field(&rec.fields, "value")) {
            (Some(Value::Str(name)), Some(value)) => {
                single = [(name.clone(), value.clone())];
                &single
            }
            _ => return None,
        },
    };
    if let Some(target) = int_of(field(values, TARGET)) {
        let mut words = String::from("move to ");
        push_py_repr(&mut words, opening_mm(target));
        words.push_str(" mm");
        for (name, before, after) in WORDS {
            if let Some(value) = field(values, name) {
                words.push(' ');
                words.push_str(before);
                push_py_str(&mut words, value);
                words.push_str(after);
            }
        }
        return Some((MOVE, Some(target), words));
    }
    (int_of(field(values, STOP_REGISTER)) == Some(1)).then(|| (STOP, None, STOP.to_owned()))
}

/// Python's `str(value)` of a register's value (the decoders give ints; the rest for safety).
fn push_py_str(out: &mut String, value: &Value) {
    match value {
        Value::Int(v) => {
            let _ = write!(out, "{v}");
        }
        Value::Bool(b) => out.push_str(if *b { "True" } else { "False" }),
        Value::Float(x) => push_py_repr(out, *x),
        Value::Str(s) => out.push_str(s),
        Value::Null => out.push_str("None"),
        other => {
            let _ = write!(out, "{other:?}");
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::model::{Str, FRAME};
    use crate::generated::cycles::CATCH as CATCH_KIND;
    use std::borrow::Cow;

    fn rec(
        protocol: &'static str,
        direction: &'static str,
        code: i64,
        fields: Vec<(Str, Value)>,
    ) -> Record {
        let mut r = Record::new(Some(2.0), Arc::from("bus"), protocol, FRAME, vec![1, 2]);
        r.direction = Some(direction);
        r.device = Some(3);
        r.code = Some(code);
        r.fields = fields.into();
        r.summary = Arc::from("catch with force 100");
        r.seq = 9;
        r
    }

    fn writes(pairs: &[(&'static str, i64)]) -> Vec<(Str, Value)> {
        let map = pairs
            .iter()
            .map(|&(k, v)| (Str::Borrowed(k), Value::Int(v)));
        vec![(Cow::Borrowed("values"), Value::Map(map.collect()))]
    }

    fn command(found: Option<(Key, Event<Arc<Said>>)>) -> Command<Arc<Said>> {
        match found {
            Some((_, Event::Command(c))) => c,
            other => panic!("not a command: {other:?}"),
        }
    }

    #[test]
    fn a_target_write_is_a_move_in_words() {
        let fields = writes(&[
            ("CMD_OPENLEN_SET", 500),
            ("CMD_FORCE_SET", 60),
            ("CMD_SPEED_SET", 80),
        ]);
        let mut r = rec(MODBUS_RTU, REQUEST, 0x10, fields);
        r.pair = Some(10);
        let c = command(event_of(&r));
        assert_eq!(
            (c.kind.as_str(), c.target, c.fate.as_str()),
            (MOVE, Some(500), ANSWERED)
        );
        assert_eq!(c.payload.words, "move to 35.0 mm speed=80 force=60 g");
        assert_eq!(c.same, vec![1, 2]);
    }

    #[test]
    fn a_single_write_of_stop_and_a_broadcast() {
        let single = vec![
            (Cow::Borrowed("name"), Value::Str(Cow::Borrowed("CMD_STOP"))),
            (Cow::Borrowed("value"), Value::Int(1)),
        ];
        let mut r = rec(MODBUS_RTU, REQUEST, 0x06, single);
        r.flags.push(UNANSWERED);
        let c = command(event_of(&r));
        assert_eq!(
            (c.kind.as_str(), c.fate.as_str(), c.broadcast),
            (STOP, NOT_ANSWERED, false)
        );
        r.device = Some(0);
        let c = command(event_of(&r));
        assert_eq!((c.fate.as_str(), c.broadcast), (NOBODY, true));
    }

    #[test]
    fn serial_commands_and_what_is_not_one() {
        let c = command(event_of(&rec(EG2_SERIAL, REQUEST, 0x10, vec![])));
        assert_eq!(
            (c.kind.as_str(), c.payload.words.as_str()),
            (CATCH_KIND, "catch with force 100")
        );
        // a seek without its position, a read, a request with errors, a CAN read
        assert!(event_of(&rec(EG2_SERIAL, REQUEST, 0x54, vec![])).is_none());
        assert!(event_of(&rec(EG2_SERIAL, REQUEST, 0xD9, vec![])).is_none());
        let mut bad = rec(EG2_SERIAL, REQUEST, 0x10, vec![]);
        bad.errors.push("checksum".into());
        assert!(event_of(&bad).is_none());
        assert!(event_of(&rec(EG2_CAN, REQUEST, 0, writes(&[("CMD_OPENLEN_SET", 1)]))).is_none());
        // a write that neither moves nor stops
        assert!(event_of(&rec(EG2_CAN, REQUEST, 1, writes(&[("CMD_STOP", 0)]))).is_none());
    }

    #[test]
    fn answers_are_responses_to_a_request() {
        let mut r = rec(EG2_SERIAL, RESPONSE, 0x10, vec![]);
        assert!(event_of(&r).is_none()); // not paired
        r.pair = Some(4);
        r.flags.push(WRITE_FAILED);
        match event_of(&r) {
            Some((
                key,
                Event::Answer {
                    request,
                    refused,
                    garbled,
                    ..
                },
            )) => {
                assert_eq!((&*key.0, key.1), ("bus", 3));
                assert_eq!((request, refused, garbled), (4, true, false));
            }
            other => panic!("not an answer: {other:?}"),
        }
    }
}
