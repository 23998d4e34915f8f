//! analyzer/cycles/rules.py: what a cycle saw, and the rules that decide its outcome. The
//! Python is the reference (its text says the rules); this is the same code, line for line,
//! for the native session's samples (tests/native/test_cycles_native.py requires equal cycles).

use crate::generated::cycles::{
    ANSWERED, AT_TARGET, CATCH, CLOSED_EMPTY, CONTACT_FORCE, FAULTED, FORCE, FULLY_CLOSED,
    FULLY_OPEN, GRIPPED, GRIPPING, NOBODY, NOT_ANSWERED, OPENED, OPENING, POSITIONED, REFUSED,
    RELEASE, SLIP, SLIP_MARGIN, STATE, STOP, STOPPED, STOPPED_FIRST, STOPPED_IDLE, TIME,
    UNANSWERED, UNFINISHED, UNKNOWN,
};

/// A motion or stop command (`commands.Command`), carrying the caller's `payload` (the Python
/// object) back out with its cycle.
#[derive(Clone, Debug)]
pub struct Command<P> {
    pub seq: i64,
    pub t: Option<f64>,
    pub kind: String,
    pub target: Option<i64>,
    pub fate: String,
    pub broadcast: bool,
    pub retransmission: bool,
    pub same: Vec<u8>,
    pub payload: P,
}

/// What is known of a gripper when a command comes (`rules.Context`).
#[derive(Clone, Copy, Debug)]
pub struct Context {
    pub state: Option<i64>,
    pub opening: Option<i64>,
    pub force_setting: Option<i64>,
    pub max_opening: i64,
    pub min_opening: i64,
    pub state_read: bool,
}

impl Default for Context {
    fn default() -> Self {
        Context {
            state: None,
            opening: None,
            force_setting: None,
            max_opening: 1000,
            min_opening: 0,
            state_read: false,
        }
    }
}

/// A frame that decided something: its seq and time.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Mark {
    pub seq: i64,
    pub t: Option<f64>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Aim {
    Close,
    Open,
    GoTo,
}

// what the cycle's readings carried (`Watch.seen`), as bits
const SEEN_STATE: u8 = 1;
const SEEN_OPENING: u8 = 2;
const SEEN_FORCE: u8 = 4;

/// A decided cycle: what `Watch.cycle` gives `build_cycle` (rules.py).
#[derive(Clone, Debug)]
pub struct Decided<P> {
    pub command: Command<P>,
    pub device: i64,
    pub target: i64,
    pub outcome: &'static str,
    pub end: Mark,
    pub width: Option<i64>,
    pub force_peak: Option<i64>,
    pub contact_t: Option<f64>,
    pub settle_t: Option<f64>,
    pub retries: usize,
    pub faults: i64,
    pub warnings: Vec<&'static str>,
    pub unknown: Vec<&'static str>,
    pub evidence: Vec<i64>,
}

/// Everything one cycle saw (`rules.Watch`).
#[derive(Debug)]
pub struct Watch<P> {
    pub command: Command<P>,
    device: i64,
    aim: Aim,
    target: i64,
    before: Context,
    reach: (f64, f64),
    pub copies: Vec<i64>,
    accepted: i64,
    answered: i64,
    cut_off: bool,
    refusals: Vec<i64>,
    answers: Vec<i64>,
    seen: u8,
    moved: bool,
    opening: Option<i64>,
    contact: Option<Mark>,
    width: Option<i64>,
    width_pending: bool,
    pub final_: Option<Mark>,
    final_state: Option<i64>,
    final_opening: Option<i64>,
    final_pending: bool,
    at_target: Option<Mark>,
    last_state: Option<i64>,
    last_state_value: Option<i64>,
    faults: i64,
    fault_mark: Option<Mark>,
    force_peak: Option<i64>,
    slip: Option<Mark>,
    stop: Option<Mark>,
    pub end: Option<Mark>,
}

/// A new cycle's watch (`rules.watch`), for `device`.
pub fn watch<P: Clone>(cmd: Command<P>, device: i64, ctx: &Context) -> Watch<P> {
    let (aim, target) = aim_of(&cmd, ctx);
    let reach = reach_of(aim, target, ctx);
    let mut w = Watch {
        command: cmd,
        device,
        aim,
        target,
        before: *ctx,
        reach,
        copies: Vec::new(),
        accepted: 0,
        answered: 0,
        cut_off: false,
        refusals: Vec::new(),
        answers: Vec::new(),
        seen: 0,
        moved: false,
        opening: None,
        contact: None,
        width: None,
        width_pending: false,
        final_: None,
        final_state: None,
        final_opening: None,
        final_pending: false,
        at_target: None,
        last_state: None,
        last_state_value: None,
        faults: 0,
        fault_mark: None,
        force_peak: None,
        slip: None,
        stop: None,
        end: None,
    };
    let (seq, fate) = (w.command.seq, w.command.fate.clone());
    w.copy(seq, &fate);
    w
}

fn aim_of<P>(cmd: &Command<P>, ctx: &Context) -> (Aim, i64) {
    if cmd.kind == CATCH {
        return (Aim::Close, ctx.min_opening);
    }
    if cmd.kind == RELEASE {
        return (Aim::Open, ctx.max_opening);
    }
    let target = cmd.target.unwrap_or(ctx.min_opening);
    if target <= ctx.min_opening {
        (Aim::Close, target)
    } else if target >= ctx.max_opening {
        (Aim::Open, target)
    } else {
        (Aim::GoTo, target)
    }
}

fn reach_of(aim: Aim, target: i64, ctx: &Context) -> (f64, f64) {
    match aim {
        Aim::Open => ((ctx.max_opening - AT_TARGET) as f64, f64::INFINITY),
        Aim::GoTo => ((target - AT_TARGET) as f64, (target + AT_TARGET) as f64),
        Aim::Close => (1.0, 0.0),
    }
}

impl<P: Clone> Watch<P> {
    /// A copy of the command (the first one too): its fate as pairing left it.
    pub fn copy(&mut self, seq: i64, fate: &str) {
        self.copies.push(seq);
        if fate == ANSWERED || fate == NOBODY {
            self.answered += 1;
            self.accepted += 1;
        } else if fate == STOPPED_FIRST {
            self.cut_off = true;
        }
    }

    pub fn answer(&mut self, seq: i64, refused: bool, garbled: bool) {
        self.answers.push(seq);
        if refused || garbled {
            self.accepted -= 1;
        }
        if refused {
            self.refusals.push(seq);
        }
    }

    pub fn accepts_retry(&self, cmd: &Command<P>) -> bool {
        if cmd.same != self.command.same {
            return false;
        }
        cmd.retransmission || self.accepted <= 0 || self.seen == 0
    }

    pub fn stopped(&mut self, seq: i64, t: Option<f64>) -> Mark {
        let mark = Mark { seq, t };
        self.stop = Some(mark);
        mark
    }

    #[allow(clippy::too_many_arguments)]
    pub fn reading(
        &mut self,
        seq: i64,
        t: Option<f64>,
        state: Option<i64>,
        opening: Option<i64>,
        force: Option<i64>,
        fault: Option<i64>,
        force_setting: Option<i64>,
    ) {
        if let Some(bits) = fault.filter(|&f| f != 0) {
            self.faults |= bits;
            if self.fault_mark.is_none() {
                self.fault_mark = Some(Mark { seq, t });
            }
        }
        if let Some(o) = opening {
            self.on_opening(seq, t, o);
        }
        if let Some(f) = force {
            self.seen |= SEEN_FORCE;
            if self.force_peak.is_none_or(|p| f > p) {
                self.force_peak = Some(f);
            }
            if let Some(setting) = force_setting.filter(|&s| s != 0) {
                if self.contact.is_none() && f as f64 >= CONTACT_FORCE * setting as f64 {
                    self.touch(seq, t, opening);
                }
            }
        }
        if let Some(s) = state {
            self.on_state(seq, t, s, opening);
        }
    }

    fn on_opening(&mut self, seq: i64, t: Option<f64>, opening: i64) {
        self.seen |= SEEN_OPENING;
        self.opening = Some(opening);
        if let Some(before) = self.before.opening {
            if (opening - before).abs() > AT_TARGET {
                self.moved = true;
            }
        }
        if self.width_pending {
            self.width = Some(opening);
            self.width_pending = false;
        } else if let Some(width) = self.width {
            if self.slip.is_none() && opening < width - SLIP_MARGIN {
                self.slip = Some(Mark { seq, t });
            }
        }
        if self.final_pending {
            self.final_opening = Some(opening);
            self.final_pending = false;
        }
        let o = opening as f64;
        if self.at_target.is_none() && self.reach.0 <= o && o <= self.reach.1 {
            self.at_target = Some(Mark { seq, t });
        }
    }

    fn on_state(&mut self, seq: i64, t: Option<f64>, state: i64, opening: Option<i64>) {
        self.seen |= SEEN_STATE;
        if self.last_state.is_none() || Some(state) != self.last_state_value {
            self.last_state = Some(seq);
            self.last_state_value = Some(state);
        }
        let standing = is_standing(state);
        if !standing {
            self.moved = true;
        }
        if self.final_.is_none() {
            if standing && self.fits(state) {
                self.final_ = Some(Mark { seq, t });
                self.final_state = Some(state);
                self.final_opening = opening.or(self.opening);
                self.final_pending = opening.is_none();
            }
        } else if self.final_state == Some(GRIPPING) && state != GRIPPING && self.slip.is_none() {
            self.slip = Some(Mark { seq, t });
        }
        if state == GRIPPING && self.contact.is_none() {
            self.touch(seq, t, opening);
        }
    }

    fn touch(&mut self, seq: i64, t: Option<f64>, opening: Option<i64>) {
        if !self.direction().1 {
            self.contact = Some(Mark { seq, t });
            self.width = opening.or(self.opening);
            self.width_pending = opening.is_none();
        }
    }

    fn fits(&self, state: i64) -> bool {
        let (closing, opening) = self.direction();
        if closing && state == FULLY_OPEN {
            return false;
        }
        if opening && (state == FULLY_CLOSED || state == GRIPPING) {
            return false;
        }
        !(state == STOPPED_IDLE && self.before.state == Some(STOPPED_IDLE) && !self.moved)
    }

    fn direction(&self) -> (bool, bool) {
        match self.aim {
            Aim::Close => (true, false),
            Aim::Open => (false, true),
            Aim::GoTo => match self.before.opening {
                None => (false, false),
                Some(now) => (self.target < now - AT_TARGET, self.target > now + AT_TARGET),
            },
        }
    }

    /// The cycle as it ended: at the frame `ended_at`, or at the end of the capture (None).
    pub fn cycle(&self, ended_at: Option<Mark>) -> Decided<P> {
        let (outcome, mut evidence) = self.outcome(ended_at.is_none());
        let cmd = &self.command;
        let end = ended_at.or(self.end).unwrap_or(Mark {
            seq: cmd.seq,
            t: cmd.t,
        });
        evidence.sort_unstable();
        evidence.dedup();
        Decided {
            command: cmd.clone(),
            device: self.device,
            target: self.target,
            outcome,
            end,
            width: self.width,
            force_peak: self.force_peak,
            contact_t: self.contact.and_then(|m| m.t),
            settle_t: self.settled(outcome).and_then(|m| m.t),
            retries: self.copies.len() - 1,
            faults: self.faults,
            warnings: self.warnings(outcome),
            unknown: self.unknown(),
            evidence,
        }
    }

    fn outcome(&self, ended_by_capture: bool) -> (&'static str, Vec<i64>) {
        let mut asked: Vec<i64> = self.copies.iter().chain(&self.answers).copied().collect();
        if self.faults != 0 {
            if let Some(mark) = self.fault_mark {
                asked.push(mark.seq);
                return (FAULTED, asked);
            }
        }
        if self.accepted <= 0 && !self.refusals.is_empty() {
            return (REFUSED, asked);
        }
        if self.answered == 0 && (self.cut_off || !(self.moved || self.final_.is_some())) {
            return (if self.cut_off { UNFINISHED } else { UNANSWERED }, asked);
        }
        if let (Some(stop), None) = (self.stop, self.final_) {
            asked.push(stop.seq);
            return (STOPPED, asked);
        }
        if let Some(fin) = self.final_ {
            asked.extend(
                [Some(fin), self.contact, self.slip]
                    .iter()
                    .flatten()
                    .map(|m| m.seq),
            );
            return (self.standing(), asked);
        }
        if self.seen & SEEN_STATE == 0 {
            if let Some(mark) = self.at_target {
                asked.push(mark.seq);
                return (
                    if self.aim == Aim::Open {
                        OPENED
                    } else {
                        POSITIONED
                    },
                    asked,
                );
            }
        }
        if self.seen & SEEN_STATE != 0 {
            if let Some(seq) = self.last_state {
                asked.push(seq);
                return (UNFINISHED, asked);
            }
        }
        if ended_by_capture && self.before.state_read {
            return (UNFINISHED, asked);
        }
        (UNKNOWN, asked)
    }

    fn warnings(&self, outcome: &str) -> Vec<&'static str> {
        let mut found = Vec::new();
        if self.slip.is_some() && self.contact.is_some() {
            found.push(SLIP);
        }
        if self.answered == 0 && outcome != UNANSWERED && outcome != UNFINISHED {
            found.push(NOT_ANSWERED);
        }
        found
    }

    fn standing(&self) -> &'static str {
        match self.final_state {
            Some(GRIPPING) => return GRIPPED,
            Some(FULLY_CLOSED) => return CLOSED_EMPTY,
            Some(FULLY_OPEN) => return OPENED,
            _ => {}
        }
        if self.aim != Aim::GoTo {
            return STOPPED;
        }
        match self.final_opening {
            None => UNKNOWN,
            Some(o) if (o - self.target).abs() <= AT_TARGET => POSITIONED,
            Some(_) => STOPPED,
        }
    }

    fn settled(&self, outcome: &str) -> Option<Mark> {
        if [GRIPPED, CLOSED_EMPTY, OPENED, POSITIONED].contains(&outcome) {
            return self.final_.or(self.at_target);
        }
        if outcome == STOPPED && self.stop.is_none() {
            self.final_
        } else {
            None
        }
    }

    fn unknown(&self) -> Vec<&'static str> {
        let mut missing: Vec<&'static str> = [
            (SEEN_STATE, STATE),
            (SEEN_OPENING, OPENING),
            (SEEN_FORCE, FORCE),
        ]
        .iter()
        .filter(|(bit, _)| self.seen & bit == 0)
        .map(|(_, name)| *name)
        .collect();
        if self.command.t.is_none() {
            missing.push(TIME);
        }
        missing
    }
}

fn is_standing(state: i64) -> bool {
    [FULLY_OPEN, FULLY_CLOSED, STOPPED_IDLE, GRIPPING].contains(&state)
}

/// STOP as a command kind (for the segmenter).
pub fn is_stop<P>(cmd: &Command<P>) -> bool {
    cmd.kind == STOP
}
