//! The bits a classic CAN 2.0 frame occupies on the wire (decoders/can_bits.py): start-of-frame
//! through the CRC sequence with the stuff bits the transmitter inserts there, plus 13 bits that
//! are never stuffed (CRC delimiter, ACK slot, ACK delimiter, 7 end-of-frame bits, 3
//! intermission bits), as the Linux kernel's `can_frame_bits()` and `canbusload -e` count them.
//! Error frames count 0 bits; CAN FD frames and frames no classic controller sends are refused.

use super::model::CanFrame;

const MAX_DATA_BYTES: usize = 8;
const MAX_DLC: usize = 15; // the DLC field has 4 bits; 9-15 still mean 8 data bytes
const SFF_ID_BITS: u32 = 11;
const EFF_EXTENSION_BITS: u32 = 18;
const STUFF_RUN: u32 = 5; // equal bits after which the transmitter inserts their complement
const CRC_BITS: u32 = 15;
/// CRC delimiter (1), ACK slot, ACK delimiter, EOF (7), intermission (3): never stuffed
const TRAILER_BITS: u32 = 1 + 9 + 3;
/// an error frame is the controller's report, not a frame on the wire
pub const ERROR_FRAME_BITS: u32 = 0;
/// CRC-15/CAN: x^15 + x^14 + x^10 + x^8 + x^7 + x^4 + x^3 + 1
const CRC15_POLYNOMIAL: u32 = 0x4599;

/// The CRC-15 of every byte value (MSB first), for `crc15`'s whole bytes.
const CRC15_TABLE: [u16; 256] = crc15_table();

const fn crc15_table() -> [u16; 256] {
    let mut table = [0u16; 256];
    let mut byte = 0;
    while byte < 256 {
        let mut crc = (byte as u32) << 7;
        let mut bit = 0;
        while bit < 8 {
            crc = if crc & 0x4000 != 0 {
                ((crc << 1) ^ CRC15_POLYNOMIAL) & 0x7FFF
            } else {
                (crc << 1) & 0x7FFF
            };
            bit += 1;
        }
        table[byte] = crc as u16;
        byte += 1;
    }
    table
}

/// CAN's CRC of the `width` low bits of `value`, sent most significant bit first: the bits
/// before a whole number of bytes one at a time, then a byte at a time.
fn crc15(value: u128, width: u32) -> u32 {
    let mut crc: u32 = 0;
    let lead = width % 8;
    for i in (width - lead..width).rev() {
        let feedback = ((value >> i) & 1) as u32 ^ ((crc >> 14) & 1);
        crc = (crc << 1) & 0x7FFF;
        if feedback == 1 {
            crc ^= CRC15_POLYNOMIAL;
        }
    }
    for k in (0..(width - lead) / 8).rev() {
        let byte = ((value >> (8 * k)) & 0xFF) as u32;
        let index = ((crc >> 7) ^ byte) & 0xFF;
        crc = ((crc << 8) ^ u32::from(CRC15_TABLE[index as usize])) & 0x7FFF;
    }
    crc
}

/// How many stuff bits a transmitter inserts into the `width` low bits of `value`, sent most
/// significant bit first: after 5 equal bits their complement, which opens the next run (a run
/// the last bit completes is stuffed too). Counted a run of equal bits at a time: a run that
/// continues `run` equal bits gets a stuff bit per 5 of them, and ends either in `rest` equal
/// bits or, when the last 5 were stuffed, in the stuff bit (a run of 1 of the other bit).
fn stuff_bit_count(value: u128, width: u32) -> u32 {
    let mut inserted = 0;
    let (mut run_bit, mut run) = (2u32, 0u32); // no bit yet
    let mut left = width; // bits not yet read, the next one at left - 1
    while left > 0 {
        let aligned = value << (128 - left); // the next bit on top
        let bit = (aligned >> 127) as u32;
        let same = if bit == 1 {
            (!aligned).leading_zeros()
        } else {
            aligned.leading_zeros()
        };
        let length = same.min(left);
        left -= length;
        let total = length + if bit == run_bit { run } else { 0 };
        inserted += total / STUFF_RUN;
        (run_bit, run) = match total % STUFF_RUN {
            0 => (1 - bit, 1),
            rest => (bit, rest),
        };
    }
    inserted
}

/// The fields from SOF through DLC as one number (dominant is 0) and its width.
fn header(arbitration_id: u32, extended: bool, remote: bool, dlc: usize) -> (u128, u32) {
    let (id, rtr, dlc) = (u128::from(arbitration_id), u128::from(remote), dlc as u128);
    if !extended {
        // SOF, identifier (11), RTR, IDE and r0 (dominant), DLC (4)
        return (id << 7 | rtr << 6 | dlc, 1 + SFF_ID_BITS + 1 + 2 + 4);
    }
    let base = id >> EFF_EXTENSION_BITS;
    let extension = id & ((1 << EFF_EXTENSION_BITS) - 1);
    // SOF, base identifier (11), SRR and IDE (recessive), extension (18), RTR, r1 and r0, DLC
    let value = base << 27 | 0b11 << 25 | extension << 7 | rtr << 6 | dlc;
    (value, 1 + SFF_ID_BITS + 2 + EFF_EXTENSION_BITS + 1 + 2 + 4)
}

/// Why a classic CAN frame cannot be this (decoders/can_bits.py `_check`), or Ok.
fn check(
    arbitration_id: u32,
    data: &[u8],
    extended: bool,
    remote: bool,
    dlc: usize,
) -> Result<(), String> {
    let id_bits = SFF_ID_BITS + if extended { EFF_EXTENSION_BITS } else { 0 };
    if u64::from(arbitration_id) >= 1u64 << id_bits {
        return Err(format!(
            "identifier {arbitration_id:#x} does not fit in {id_bits} bits"
        ));
    }
    if data.len() > MAX_DATA_BYTES {
        return Err(format!(
            "{} data bytes: a CAN FD frame, whose bits are not counted",
            data.len()
        ));
    }
    if dlc > MAX_DLC {
        return Err(format!("DLC {dlc} does not fit in the 4-bit DLC field"));
    }
    if remote && !data.is_empty() {
        return Err("a remote frame carries no data".to_string());
    }
    if !remote && data.len() != dlc.min(MAX_DATA_BYTES) {
        return Err(format!("DLC {dlc} but {} data bytes", data.len()));
    }
    Ok(())
}

/// The bits the frame takes on the bus, stuff bits and the 3 intermission bits included.
pub fn exact_bits(
    arbitration_id: u32,
    data: &[u8],
    extended: bool,
    remote: bool,
    dlc: usize,
) -> Result<u32, String> {
    check(arbitration_id, data, extended, remote, dlc)?;
    let (mut value, mut width) = header(arbitration_id, extended, remote, dlc);
    for &byte in data {
        value = value << 8 | u128::from(byte);
        width += 8;
    }
    let stuffed = value << CRC_BITS | u128::from(crc15(value, width));
    let span = width + CRC_BITS;
    Ok(span + stuff_bit_count(stuffed, span) + TRAILER_BITS)
}

/// `exact_bits` of a captured frame, for bus load: 0 for an error frame, Err for CAN FD.
pub fn frame_bits(frame: &CanFrame) -> Result<u32, String> {
    if frame.is_error {
        return Ok(ERROR_FRAME_BITS);
    }
    if frame.is_fd {
        return Err("CAN FD frame: its bits are not counted (classic CAN only)".to_string());
    }
    let data: &[u8] = if frame.is_remote { &[] } else { &frame.data };
    exact_bits(
        frame.arbitration_id,
        data,
        frame.is_extended,
        frame.is_remote,
        frame.length(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn stuffing_counts_runs_and_the_stuff_bit_opens_the_next() {
        assert_eq!(stuff_bit_count(0b0000011111, 10), 2);
        assert_eq!(stuff_bit_count(0b00000, 5), 1);
        assert_eq!(stuff_bit_count(0b0000100001, 10), 0);
    }

    /// The bit-by-bit count, for the run-by-run one.
    fn stuff_bits_one_by_one(value: u128, width: u32) -> u32 {
        let (mut inserted, mut run_bit, mut run) = (0, 2, 0);
        for i in (0..width).rev() {
            let bit = ((value >> i) & 1) as u32;
            run = if bit == run_bit { run + 1 } else { 1 };
            run_bit = bit;
            if run == STUFF_RUN {
                inserted += 1;
                (run_bit, run) = (1 - bit, 1);
            }
        }
        inserted
    }

    /// The bit-by-bit CRC, for the table's.
    fn crc15_one_by_one(value: u128, width: u32) -> u32 {
        let mut crc = 0;
        for i in (0..width).rev() {
            let feedback = ((value >> i) & 1) as u32 ^ ((crc >> 14) & 1);
            crc = (crc << 1) & 0x7FFF;
            if feedback == 1 {
                crc ^= CRC15_POLYNOMIAL;
            }
        }
        crc
    }

    #[test]
    fn counts_by_runs_and_bytes_are_counts_bit_by_bit() {
        let mut x: u128 = 0x9E37_79B9_7F4A_7C15_F39C_C060_5CED_C834;
        for width in 1..=118 {
            for _ in 0..200 {
                x ^= x << 13;
                x ^= x >> 7;
                x ^= x << 17;
                // long runs as often as not: that is where stuffing happens
                let v = (x & (x >> 3) | (x >> 64) & (x >> 71)) & ((1u128 << width) - 1);
                assert_eq!(stuff_bit_count(v, width), stuff_bits_one_by_one(v, width));
                assert_eq!(crc15(v, width), crc15_one_by_one(v, width));
            }
        }
    }

    #[test]
    fn known_frames() {
        // the bounds every frame lies between: 47/67 + 8n bits unstuffed, worst case stuffed
        for (extended, base) in [(false, 47), (true, 67)] {
            for n in 0..=8usize {
                let data: Vec<u8> = (0..n as u8).map(|i| i.wrapping_mul(37)).collect();
                let bits = exact_bits(0x123, &data, extended, false, n).unwrap();
                let unstuffed = base + 8 * n as u32;
                assert!(bits >= unstuffed && bits <= unstuffed + unstuffed / 4 + 1);
            }
        }
        // identifier 0, no data: 19 zeros from SOF to DLC and a zero CRC, 34 zeros with a stuff
        // bit after bits 5, 10, ..., 30 (each stuff bit opens a run of its own): 34 + 6 + 13
        assert_eq!(exact_bits(0, &[], false, false, 0).unwrap(), 53);
    }

    #[test]
    fn refusals() {
        assert!(exact_bits(0x800, &[], false, false, 0).is_err());
        assert!(exact_bits(1, &[1, 2], false, false, 1).is_err());
        assert!(exact_bits(1, &[1], false, true, 1).is_err());
        let mut frame = CanFrame {
            is_fd: true,
            ..CanFrame::default()
        };
        assert!(frame_bits(&frame).is_err());
        frame.is_fd = false;
        frame.is_error = true;
        assert_eq!(frame_bits(&frame), Ok(0));
    }
}
