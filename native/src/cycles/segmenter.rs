//! analyzer/cycles/segmenter.py: each gripper's timeline cut into cycles. The Python is the
//! reference (its text says how); this is the same code for the native session's samples,
//! run in one pass over a batch (see `Segmenter::feed`), giving the same cycles in the same
//! order.

use super::rules::{is_stop, watch, Command, Context, Decided, Mark, Watch};
use crate::hash::FastMap;
use std::sync::Arc;

/// A reading's values: `listener.FIELDS` (state, opening, force, fault, force_setting,
/// max_opening, min_opening), None where the frame did not carry one.
pub type Values = [Option<i64>; 7];

/// A gripper: (bus, device).
pub type Key = (Arc<str>, i64);

/// A command or an answer to a gripper.
#[derive(Clone, Debug)]
pub enum Event<P> {
    Command(Command<P>),
    /// the response (`seq`) to the request `request`
    Answer {
        seq: i64,
        t: Option<f64>,
        request: i64,
        refused: bool,
        garbled: bool,
    },
}

impl<P> Event<P> {
    fn seq(&self) -> i64 {
        match self {
            Event::Command(c) => c.seq,
            Event::Answer { seq, .. } => *seq,
        }
    }

    fn t(&self) -> Option<f64> {
        match self {
            Event::Command(c) => c.t,
            Event::Answer { t, .. } => *t,
        }
    }
}

/// A reading of gripper number `gripper`; `kind`: which fields it carries (its holder).
#[derive(Clone, Debug)]
pub struct Reading {
    pub gripper: usize,
    pub seq: i64,
    pub t: Option<f64>,
    pub values: Values,
    pub kind: u16,
}

struct Gripper<P> {
    device: i64,
    context: Context,
    watch: Option<Watch<P>>,
    heard: bool,
    /// the last values of each kind of reading
    holders: Vec<(u16, Option<Values>)>,
}

/// Cuts every gripper's events into cycles (`segmenter.Segmenter`).
pub struct Segmenter<P> {
    index: FastMap<Key, usize>,
    keys: Vec<Key>,
    grippers: Vec<Gripper<P>>,
    /// the cycles that ended, with their bus (for the order of those that end together)
    cycles: Vec<(Arc<str>, Decided<P>)>,
}

impl<P: Clone> Default for Segmenter<P> {
    fn default() -> Self {
        Segmenter {
            index: FastMap::default(),
            keys: Vec::new(),
            grippers: Vec::new(),
            cycles: Vec::new(),
        }
    }
}

impl<P: Clone> Segmenter<P> {
    /// The gripper's number (made when new: the Python's `_gripper`).
    pub fn gripper(&mut self, key: &Key) -> usize {
        if let Some(&i) = self.index.get(key) {
            return i;
        }
        self.keys.push(key.clone());
        self.grippers.push(Gripper {
            device: key.1,
            context: Context::default(),
            watch: None,
            heard: false,
            holders: Vec::new(),
        });
        self.index.insert(key.clone(), self.grippers.len() - 1);
        self.grippers.len() - 1
    }

    /// One batch (`Segmenter.feed`): its `readings` in the order of its samples (their
    /// grippers numbered by `gripper`, in the order they first appear, as the Python's
    /// `holder` calls make them), and the `(bus, device, event)` of its commands and answers.
    ///
    /// The Python runs each gripper's events in seq order, a command before the reading of its
    /// own record, one gripper after another; a gripper's run touches no other gripper, so
    /// this runs every event in one pass in that order instead (the cycles that end are
    /// sorted by `take` whatever the order they ended in).
    pub fn feed(&mut self, mut readings: Vec<Reading>, commands: Vec<(Key, Event<P>)>) {
        let mut targeted: Vec<(usize, Event<P>)> = Vec::with_capacity(commands.len());
        for (key, event) in commands {
            match &event {
                Event::Command(c) if c.broadcast => {
                    for g in self.broadcast_keys(&key.0, &readings) {
                        targeted.push((g, event.clone()));
                    }
                }
                _ => {
                    let g = self.gripper(&key);
                    targeted.push((g, event));
                }
            }
        }
        targeted.sort_by_key(|(_, e)| e.seq()); // stable: in the order they came
        if !readings.is_sorted_by_key(|r| r.seq) {
            readings.sort_by_key(|r| r.seq);
        }
        // the last frame of each gripper in this batch, by gripper number (a few grippers)
        let mut last: Vec<Option<Mark>> = vec![None; self.grippers.len()];
        let mut commands = targeted.iter().peekable();
        for r in &readings {
            while let Some((g, event)) = commands.next_if(|(_, e)| e.seq() <= r.seq) {
                self.event(*g, event);
                last[*g] = Some(Mark {
                    seq: event.seq(),
                    t: event.t(),
                });
            }
            self.reading(r.gripper, r.seq, r.t, &r.values, r.kind);
            last[r.gripper] = Some(Mark { seq: r.seq, t: r.t });
        }
        for (g, event) in commands {
            self.event(*g, event);
            last[*g] = Some(Mark {
                seq: event.seq(),
                t: event.t(),
            });
        }
        for (g, mark) in last.into_iter().enumerate() {
            if let (Some(mark), Some(w)) = (mark, self.grippers[g].watch.as_mut()) {
                w.end = Some(mark);
            }
        }
    }

    /// The grippers a broadcast on `bus` goes to: those heard so far and those with readings
    /// in this batch, in (bus, device) order.
    fn broadcast_keys(&mut self, bus: &Arc<str>, readings: &[Reading]) -> Vec<usize> {
        let mut found: Vec<usize> = (0..self.grippers.len())
            .filter(|&g| self.grippers[g].heard && &self.keys[g].0 == bus)
            .chain(
                readings
                    .iter()
                    .map(|r| r.gripper)
                    .filter(|&g| &self.keys[g].0 == bus),
            )
            .collect();
        found.sort_by(|a, b| self.keys[*a].cmp(&self.keys[*b]));
        found.dedup();
        found
    }

    /// The cycles that ended since the last call, in the order they ended (then began; then
    /// by gripper: a broadcast's cycles end together).
    pub fn take(&mut self) -> Vec<Decided<P>> {
        let mut done = std::mem::take(&mut self.cycles);
        done.sort_by(|(a_bus, a), (b_bus, b)| {
            let a_key = (a.end.seq, a.command.seq, a_bus, a.device);
            a_key.cmp(&(b.end.seq, b.command.seq, b_bus, b.device))
        });
        done.into_iter().map(|(_, c)| c).collect()
    }

    /// The end of the capture: every cycle in progress ends (in the order they began, then
    /// by gripper).
    pub fn finish(&mut self) -> Vec<Decided<P>> {
        for g in 0..self.grippers.len() {
            self.end(g, None);
        }
        let mut done = std::mem::take(&mut self.cycles);
        done.sort_by(|(a_bus, a), (b_bus, b)| {
            (a.command.seq, a_bus, a.device).cmp(&(b.command.seq, b_bus, b.device))
        });
        done.into_iter().map(|(_, c)| c).collect()
    }

    /// A command or an answer to gripper `g`.
    fn event(&mut self, g: usize, event: &Event<P>) {
        match event {
            Event::Command(cmd) => {
                if !cmd.broadcast || self.grippers[g].heard {
                    self.start(g, cmd);
                }
            }
            Event::Answer {
                seq,
                request,
                refused,
                garbled,
                ..
            } => {
                if let Some(w) = self.grippers[g].watch.as_mut() {
                    if w.copies.contains(request) {
                        w.answer(*seq, *refused, *garbled);
                    }
                }
            }
        }
    }

    fn reading(&mut self, g: usize, seq: i64, t: Option<f64>, values: &Values, kind: u16) {
        let gripper = &mut self.grippers[g];
        let undecided = gripper.watch.as_ref().is_some_and(|w| w.final_.is_none());
        let holder = match gripper.holders.iter().position(|(k, _)| *k == kind) {
            Some(i) => &mut gripper.holders[i].1,
            None => {
                gripper.holders.push((kind, None));
                &mut gripper.holders.last_mut().expect("just pushed").1
            }
        };
        if holder.as_ref() == Some(values) && !undecided {
            return; // the same again: nothing new for a cycle already decided
        }
        *holder = Some(*values);
        let [state, opening, force, fault, force_setting, max_opening, min_opening] = *values;
        let ctx = &mut gripper.context;
        if let Some(v) = force_setting {
            ctx.force_setting = Some(v);
        }
        if let Some(v) = max_opening {
            ctx.max_opening = v;
        }
        if let Some(v) = min_opening {
            ctx.min_opening = v;
        }
        if state.is_none() && opening.is_none() && force.is_none() && fault.is_none() {
            return; // a setting: no reading
        }
        gripper.heard = true;
        if let Some(w) = gripper.watch.as_mut() {
            w.reading(seq, t, state, opening, force, fault, ctx.force_setting);
        }
        if state.is_some() {
            ctx.state = state;
            ctx.state_read = true;
        }
        if opening.is_some() {
            ctx.opening = opening;
        }
    }

    fn start(&mut self, g: usize, cmd: &Command<P>) {
        if is_stop(cmd) {
            if let Some(w) = self.grippers[g].watch.as_mut() {
                let mark = w.stopped(cmd.seq, cmd.t);
                self.end(g, Some(mark));
            }
            return;
        }
        if let Some(w) = self.grippers[g].watch.as_mut() {
            if w.accepts_retry(cmd) {
                w.copy(cmd.seq, &cmd.fate);
                return;
            }
        }
        self.end(
            g,
            Some(Mark {
                seq: cmd.seq,
                t: cmd.t,
            }),
        );
        let gripper = &mut self.grippers[g];
        gripper.watch = Some(watch(cmd.clone(), gripper.device, &gripper.context));
        for (_, holder) in gripper.holders.iter_mut() {
            *holder = None; // a new cycle reads everything again
        }
    }

    fn end(&mut self, g: usize, ended_at: Option<Mark>) {
        if let Some(w) = self.grippers[g].watch.take() {
            self.cycles
                .push((self.keys[g].0.clone(), w.cycle(ended_at)));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::generated::cycles::{ANSWERED, CATCH, GRIPPED, UNFINISHED};

    fn catch(seq: i64) -> Event<()> {
        Event::Command(Command {
            seq,
            t: Some(seq as f64 / 100.0),
            kind: CATCH.to_owned(),
            target: None,
            fate: ANSWERED.to_owned(),
            broadcast: false,
            retransmission: false,
            same: vec![1, 2, 3],
            payload: (),
        })
    }

    fn reading(gripper: usize, seq: i64, state: i64, opening: i64) -> Reading {
        let mut values: Values = [None; 7];
        values[0] = Some(state);
        values[1] = Some(opening);
        Reading {
            gripper,
            seq,
            t: Some(seq as f64 / 100.0),
            values,
            kind: 0b11,
        }
    }

    #[test]
    fn a_catch_that_stops_on_the_force_limit_is_gripped_at_its_width() {
        let mut s: Segmenter<()> = Segmenter::default();
        let key: Key = (Arc::from("can0"), 1);
        let g = s.gripper(&key);
        s.feed(vec![reading(g, 0, 1, 1000)], vec![]);
        let moving = (2..6).map(|i| reading(g, i, 4, 1000 - 100 * i));
        let readings = moving.chain([reading(g, 6, 6, 450), reading(g, 7, 6, 450)]);
        s.feed(readings.collect(), vec![(key.clone(), catch(1))]);
        assert!(s.take().is_empty(), "a cycle ends at the next command");
        s.feed(vec![], vec![(key, catch(8))]);
        let done = s.take();
        assert_eq!(done.len(), 1);
        let c = &done[0];
        assert_eq!((c.outcome, c.width, c.end.seq), (GRIPPED, Some(450), 8));
        assert_eq!(c.evidence, vec![1, 6]);
        let rest = s.finish();
        assert_eq!(rest.len(), 1);
        assert_eq!(rest[0].outcome, UNFINISHED);
    }
}
