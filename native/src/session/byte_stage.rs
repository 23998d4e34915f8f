//! The decoding of one byte stream: analyzer/session/stage.py `Decoding` for a session whose
//! input is a single byte stream (a raw serial or Modbus dump replayed), and the stream of
//! `decode`'s own run of a raw dump (offline_run.rs).
//!
//! The same stages as `Decoding.feed` / `tick` / `gap` / `cut_off` / `finish` / `stop` for its
//! one stream: the protocol fixed or detected from the first `DETECT_BYTES` (the chunks held
//! until then are replayed one by one, with their times), the stream decoder, the timing
//! linter, then request/response pairing.

use crate::decoders::eg2_serial::Eg2SerialDecoder;
use crate::decoders::framing::StreamDecoder;
use crate::decoders::lint::TimingLinter;
use crate::decoders::modbus_rtu::ModbusRtuDecoder;
use crate::decoders::model::{Record, EG2_SERIAL, MODBUS_RTU};
use crate::decoders::pairing::Pairer;
use crate::decoders::registry::detect_protocol;
use std::sync::Arc;

/// Bytes of a stream looked at before choosing its protocol (analyzer/session/stage.py).
pub const DETECT_BYTES: usize = 4096;

/// The stream decoder of the protocol chosen.
pub(crate) enum ByteDecoder {
    Serial(Box<Eg2SerialDecoder>),
    Modbus(Box<ModbusRtuDecoder>),
}

impl ByteDecoder {
    pub(crate) fn get(&mut self) -> &mut dyn StreamDecoder {
        match self {
            ByteDecoder::Serial(d) => &mut **d,
            ByteDecoder::Modbus(d) => &mut **d,
        }
    }

    /// Python `feed(Chunk(data, t, direction))`.
    fn feed_chunk(
        &mut self,
        data: &[u8],
        t: Option<f64>,
        direction: Option<&'static str>,
        out: &mut Vec<Record>,
    ) {
        match self {
            ByteDecoder::Serial(d) => d.feed_chunk(data, t, direction, out),
            ByteDecoder::Modbus(d) => d.feed_chunk(data, t, direction, out),
        }
    }

    fn idle(&mut self, now: f64, out: &mut Vec<Record>) {
        match self {
            ByteDecoder::Serial(d) => d.idle(now, out),
            ByteDecoder::Modbus(d) => d.idle(now, out),
        }
    }
}

/// A chunk read before the protocol was chosen: its bytes, time and direction.
type HeldChunk = (Vec<u8>, Option<f64>, Option<&'static str>);

/// One byte stream (`Decoding._streams` / `_undetected` for its one key).
pub(crate) struct ByteStream {
    pub(crate) bus: Arc<str>,
    /// the protocol to use (None: detect)
    pub(crate) protocol: Option<&'static str>,
    /// the protocol the bus was named after (`Decoding.per_bus`): fixes it when the stream
    /// starts, or at its next chunk while it is undetected, as `protocol` does
    named: Option<&'static str>,
    pub(crate) dec: Option<ByteDecoder>,
    /// chunks read before the protocol was chosen (replayed one by one, as the Python does)
    undetected: Vec<HeldChunk>,
    undetected_len: usize,
}

impl ByteStream {
    pub(crate) fn new(bus: Arc<str>, protocol: Option<&'static str>) -> Self {
        ByteStream {
            bus,
            protocol,
            named: None,
            dec: None,
            undetected: Vec::new(),
            undetected_len: 0,
        }
    }

    fn new_decoder(&mut self, protocol: &'static str) -> &mut ByteDecoder {
        let mut dec = if protocol == MODBUS_RTU {
            ByteDecoder::Modbus(Box::new(ModbusRtuDecoder::new(self.bus.clone())))
        } else {
            ByteDecoder::Serial(Box::new(Eg2SerialDecoder::new(self.bus.clone())))
        };
        dec.get().start_at(0);
        self.dec.insert(dec)
    }

    fn sample(&self) -> Vec<u8> {
        self.undetected
            .iter()
            .flat_map(|c| c.0.iter().copied())
            .collect()
    }

    /// `_choose`: the protocol the held sample shows, or the regular serial protocol.
    fn choose(&self) -> &'static str {
        detect_protocol(&self.sample()).unwrap_or(EG2_SERIAL)
    }

    /// `_replay`: the held chunks into the decoder, in order.
    fn replay(&mut self, out: &mut Vec<Record>) {
        let chunks = std::mem::take(&mut self.undetected);
        self.undetected_len = 0;
        let dec = self.dec.as_mut().expect("a decoder was chosen");
        for (data, t, direction) in &chunks {
            dec.feed_chunk(data, *t, *direction, out);
        }
    }

    /// The held chunk, and whether the protocol is now chosen (`_start_stream`): fixed, or
    /// `DETECT_BYTES` held.
    fn hold(&mut self, data: &[u8], t: Option<f64>, direction: Option<&'static str>) -> bool {
        self.undetected.push((data.to_vec(), t, direction));
        self.undetected_len += data.len();
        let protocol = match self.named.or(self.protocol) {
            Some(p) => p,
            None if self.undetected_len < DETECT_BYTES => return false,
            None => self.choose(),
        };
        self.new_decoder(protocol);
        true
    }

    /// `detect` for the offline run: the chunk is held until the protocol is chosen; then the
    /// bytes held (this chunk included) are handed back, to be fed as any other bytes (the
    /// decoders give the same records in any chunking, so slices of them give what the
    /// Python's replay of whole chunks gives).
    pub(crate) fn detect(&mut self, data: &[u8]) -> Option<Vec<u8>> {
        if !self.hold(data, None, None) {
            return None;
        }
        self.undetected_len = 0;
        Some(self.sample_and_clear())
    }

    fn sample_and_clear(&mut self) -> Vec<u8> {
        let sample = self.sample();
        self.undetected.clear();
        sample
    }

    /// `Decoding.feed` of one chunk: held until the protocol is chosen, then decoded.
    pub(crate) fn feed_chunk(
        &mut self,
        data: &[u8],
        t: Option<f64>,
        direction: Option<&'static str>,
        out: &mut Vec<Record>,
    ) {
        match self.dec.as_mut() {
            Some(dec) => dec.feed_chunk(data, t, direction, out),
            None => {
                if self.hold(data, t, direction) {
                    self.replay(out);
                }
            }
        }
    }

    /// Feed bytes of no time to the chosen decoder.
    pub(crate) fn feed(&mut self, data: &[u8], out: &mut Vec<Record>) {
        let dec = self.dec.as_mut().expect("a decoder was chosen").get();
        dec.feed(data, None, out);
    }

    /// `_decide_undetected`: choose if still undecided and replay what is held.
    fn decide(&mut self, out: &mut Vec<Record>) {
        if self.dec.is_none() && !self.undetected.is_empty() {
            let protocol = self.protocol.unwrap_or_else(|| self.choose());
            self.new_decoder(protocol);
            self.replay(out);
        }
    }

    /// `Decoding.finish` for the stream: choose if still undecided, then decide held bytes.
    pub(crate) fn finish(&mut self, out: &mut Vec<Record>) {
        self.decide(out);
        if let Some(dec) = self.dec.as_mut() {
            dec.get().finish(out);
        }
    }

    /// `Decoding.stop` for the stream: as `finish`, a frame begun cut off by the stop.
    fn stop(&mut self, out: &mut Vec<Record>) {
        self.decide(out);
        if let Some(dec) = self.dec.as_mut() {
            dec.get().stop(out);
        }
    }

    /// `Decoding.tick` for the stream: a stream still undetected is decided once its sample
    /// shows a protocol; quiet bytes held are decided.
    fn tick(&mut self, now: f64, out: &mut Vec<Record>) {
        if self.dec.is_none() && !self.undetected.is_empty() {
            if let Some(protocol) = self.protocol.or_else(|| detect_protocol(&self.sample())) {
                self.new_decoder(protocol);
                self.replay(out);
            }
        }
        if let Some(dec) = self.dec.as_mut() {
            dec.idle(now, out);
        }
    }
}

/// `Decoding` for one byte stream: chunks in, records out in stream order.
pub struct ByteStage {
    /// the protocol of the stream (None: detect)
    protocol: Option<&'static str>,
    /// buses named after their protocol (`Decoding.per_bus`)
    named: Vec<(Arc<str>, &'static str)>,
    stream: Option<(Arc<str>, Arc<str>, ByteStream)>,
    linter: TimingLinter,
    pairer: Pairer,
    decoded: Vec<Record>,
}

impl ByteStage {
    /// `Decoding(protocol, positional_seq=positional)`.
    pub fn new(protocol: Option<&'static str>, positional: bool) -> Self {
        ByteStage {
            protocol,
            named: Vec::new(),
            stream: None,
            linter: TimingLinter::new(),
            pairer: Pairer::new(positional),
            decoded: Vec::new(),
        }
    }

    /// `Decoding.set_protocol`: `bus` speaks `protocol`. Read when its stream starts, and at
    /// its next chunk while it is still undetected (the Python starts it again then); a stream
    /// decoding already keeps its protocol.
    pub fn set_protocol(&mut self, bus: &str, protocol: &'static str) {
        self.named.retain(|(b, _)| **b != *bus);
        self.named.push((Arc::from(bus), protocol));
        if let Some((b, _, s)) = &mut self.stream {
            if **b == *bus {
                s.named = Some(protocol);
            }
        }
    }

    /// The (bus, stream) this stage decodes: the first one fed (None before).
    pub fn stream(&self) -> Option<(&str, &str)> {
        self.stream.as_ref().map(|(b, s, _)| (&**b, &**s))
    }

    /// One chunk of stream `stream` of bus `bus`: Err when it is not the stream this stage
    /// decodes (the first one fed).
    pub fn feed(
        &mut self,
        (bus, stream): (&str, &str),
        chunk: (&[u8], Option<f64>, Option<&'static str>),
        out: &mut Vec<Record>,
    ) -> Result<(), String> {
        let decoded = &mut self.decoded;
        match &mut self.stream {
            Some((b, s, byte_stream)) if **b == *bus && **s == *stream => {
                byte_stream.feed_chunk(chunk.0, chunk.1, chunk.2, decoded)
            }
            Some((b, s, _)) => {
                return Err(format!(
                    "one byte stream per native decoding: ({b:?}, {s:?}) then ({bus:?}, {stream:?})"
                ))
            }
            None => {
                let name: Arc<str> = Arc::from(bus);
                let mut byte_stream = ByteStream::new(name.clone(), self.protocol);
                byte_stream.named = self.named.iter().find(|(b, _)| **b == *bus).map(|x| x.1);
                byte_stream.feed_chunk(chunk.0, chunk.1, chunk.2, decoded);
                self.stream = Some((name, Arc::from(stream), byte_stream));
            }
        }
        self.post(out);
        Ok(())
    }

    /// Idle: a quiet stream decides its held bytes, requests that timed out are released.
    pub fn tick(&mut self, now: f64, out: &mut Vec<Record>) {
        if let Some((_, _, s)) = &mut self.stream {
            s.tick(now, &mut self.decoded);
        }
        self.post(out);
        self.pairer.tick(now, out);
    }

    /// The source of `bus` went away: its held bytes are decided, its waiting requests
    /// released (a stream still undetected stays held, as in the Python).
    pub fn gap(&mut self, bus: &str, out: &mut Vec<Record>) {
        if let Some((b, _, s)) = &mut self.stream {
            if **b == *bus {
                if let Some(dec) = s.dec.as_mut() {
                    dec.get().finish(&mut self.decoded);
                }
            }
        }
        self.post(out);
        self.pairer.gap(bus, out);
    }

    /// The end of the input: held bytes decided, waiting requests unanswered.
    pub fn finish(&mut self, out: &mut Vec<Record>) {
        if let Some((_, _, s)) = &mut self.stream {
            s.finish(&mut self.decoded);
        }
        self.post(out);
        self.pairer.flush(out);
    }

    /// The capture of `bus` was stopped (None: the whole capture): a frame begun and the
    /// requests waiting are cut off.
    pub fn cut_off(&mut self, bus: Option<&str>, out: &mut Vec<Record>) {
        if let Some((b, _, s)) = &mut self.stream {
            if bus.is_none_or(|bus| **b == *bus) {
                s.stop(&mut self.decoded);
            }
        }
        self.post(out);
        self.pairer.cut_off(bus, out);
    }

    /// `Decoding._post`: lint and pairing of what the stream decoded.
    fn post(&mut self, out: &mut Vec<Record>) {
        for mut rec in self.decoded.drain(..) {
            self.linter.check(&mut rec);
            self.pairer.push(rec, out);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::decoders::flags::{CUT_OFF, UNANSWERED};
    use crate::decoders::model::{CUT_OFF as CUT_OFF_KIND, FRAME, REQUEST, RESPONSE};

    /// A read of the opening (0x0E... the regular protocol's header, id 1) and its answer.
    fn serial(cmd: u8, body: &[u8], request: bool) -> Vec<u8> {
        let mut f = if request {
            vec![0xEB, 0x90]
        } else {
            vec![0xEE, 0x16]
        };
        f.push(1);
        f.push(body.len() as u8 + 1);
        f.push(cmd);
        f.extend_from_slice(body);
        let sum: u32 = f[2..].iter().map(|&b| b as u32).sum();
        f.push(sum as u8);
        f
    }

    fn run(stage: &mut ByteStage, chunks: &[&[u8]]) -> Vec<Record> {
        let mut out = Vec::new();
        for c in chunks {
            stage
                .feed(("serial", ""), (c, None, None), &mut out)
                .unwrap();
        }
        out
    }

    #[test]
    fn detects_pairs_and_finishes_in_any_chunking() {
        let mut bytes = serial(0x14, &[], true);
        bytes.extend(serial(0x14, &[0; 6], false));
        bytes.extend(serial(0x14, &[], true)); // never answered
        let whole = {
            let mut s = ByteStage::new(None, true);
            let mut out = run(&mut s, &[&bytes]);
            s.finish(&mut out);
            out
        };
        assert_eq!(whole.len(), 3);
        assert_eq!(whole[0].direction, Some(REQUEST));
        assert_eq!(whole[1].direction, Some(RESPONSE));
        assert_eq!(whole[0].pair, Some(whole[1].seq));
        assert_eq!(whole[2].flags, vec![UNANSWERED]);
        let mut s = ByteStage::new(None, true);
        let singles: Vec<&[u8]> = bytes.chunks(1).collect();
        let mut out = run(&mut s, &singles);
        s.finish(&mut out);
        let seqs = |r: &[Record]| r.iter().map(|x| (x.seq, x.kind)).collect::<Vec<_>>();
        assert_eq!(seqs(&out), seqs(&whole));
        assert!(out.iter().all(|r| r.kind == FRAME));
    }

    #[test]
    fn a_stop_cuts_off_the_frame_begun_and_the_request_waiting() {
        let mut s = ByteStage::new(Some(EG2_SERIAL), true);
        let request = serial(0x14, &[], true);
        let mut out = run(&mut s, &[&request, &[0xEB, 0x90, 0x01]]);
        assert!(out.is_empty(), "the request waits, the frame begun is held");
        s.cut_off(None, &mut out);
        assert_eq!(out.len(), 2);
        assert_eq!(out[0].flags, vec![CUT_OFF]);
        assert_eq!(out[1].kind, CUT_OFF_KIND);
        assert!(out[1].errors.is_empty(), "a stop is no error of the bus");
        assert_eq!(&*out[1].summary, "frame cut off by the stop (3 bytes)");
    }

    #[test]
    fn a_second_stream_is_refused() {
        let mut s = ByteStage::new(Some(EG2_SERIAL), true);
        let mut out = Vec::new();
        s.feed(("serial", ""), (&[0xEB], None, None), &mut out)
            .unwrap();
        let err = s
            .feed(("rs485", ""), (&[0xEB], None, None), &mut out)
            .unwrap_err();
        assert!(err.contains("rs485"), "{err}");
    }
}
