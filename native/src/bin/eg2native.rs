//! `eg2native FILE [--format jsonl|csv|text] [-p serial|modbus] [--bus B] [--device N] [-e]
//! [--absolute-time] [--colour]`: the native decode path on its own (no Python), for the
//! differential tests and the benchmarks. Output and exit codes as `eg2scope decode FILE
//! --jobs 1` (analyzer/commands/decode.py, common.py `finish_capture`, cli.py).

use eg2scope_native::model::{EG2_CAN, EG2_SERIAL, MODBUS_RTU};
use eg2scope_native::pipeline::{reader_for, DecodeOptions, DecodeRun, ReaderKind};
use eg2scope_native::writers::{Format, TextOptions};
use std::io::{self, Write};
use std::path::PathBuf;
use std::process::ExitCode;

const EXIT_ERROR: u8 = 1;
const EXIT_USAGE: u8 = 2;
const EXIT_DAMAGED: u8 = 3;

/// Output bytes per batch pulled from the pipeline.
const BATCH: usize = 1 << 20;

const USAGE: &str = "usage: eg2native FILE [--format jsonl|csv|text] [-p serial|modbus] \
                     [--bus NAME] [--device N] [-e] [--absolute-time] [--colour]";

fn usage(msg: &str) -> ExitCode {
    eprintln!("{USAGE}\neg2native: error: {msg}");
    ExitCode::from(EXIT_USAGE)
}

/// decoders/registry.py `resolve_protocol` ("auto": detect).
fn protocol(name: &str) -> Result<Option<&'static str>, String> {
    match name.to_lowercase().as_str() {
        "auto" => Ok(None),
        "serial" | "eg2-serial" | "rs232" => Ok(Some(EG2_SERIAL)),
        "modbus" | "modbus-rtu" | "rs485" => Ok(Some(MODBUS_RTU)),
        "can" | "eg2-can" => Ok(Some(EG2_CAN)),
        _ => Err(format!("unknown protocol {name:?}")),
    }
}

struct Args {
    file: PathBuf,
    opts: DecodeOptions,
}

fn parse(mut argv: impl Iterator<Item = String>) -> Result<Args, String> {
    let mut file = None;
    let mut opts = DecodeOptions {
        protocol: None,
        bus: None,
        device: None,
        errors_only: false,
        format: Format::Text,
        text: TextOptions::default(),
    };
    while let Some(arg) = argv.next() {
        let (flag, inline) = match arg.split_once('=') {
            Some((f, v)) if f.starts_with("--") => (f.to_string(), Some(v.to_string())),
            _ => (arg.clone(), None),
        };
        let mut value = |name: &str| {
            inline
                .clone()
                .or_else(|| argv.next())
                .ok_or_else(|| format!("argument {name}: expected one argument"))
        };
        match flag.as_str() {
            "--format" | "-f" => {
                opts.format = match value("--format")?.as_str() {
                    "jsonl" => Format::Jsonl,
                    "csv" => Format::Csv,
                    "text" => Format::Text,
                    other => return Err(format!("argument --format: invalid choice: {other:?}")),
                }
            }
            "--protocol" | "-p" => opts.protocol = protocol(&value("--protocol")?)?,
            "--bus" => opts.bus = Some(value("--bus")?),
            "--device" | "-d" => {
                let v = value("--device")?;
                let n: i64 = v
                    .parse()
                    .map_err(|_| format!("not a whole number: {v:?}"))?;
                if n < 0 {
                    return Err(format!("must be 0 or more, not {n}"));
                }
                opts.device = Some(n);
            }
            "--errors-only" | "-e" => opts.errors_only = true,
            "--absolute-time" => opts.text.absolute_time = true,
            "--colour" | "--color" => opts.text.colour = true,
            "--no-progress" => {}
            "--jobs" | "-j" => {
                value("--jobs")?; // one process always: accepted for drop-in command lines
            }
            f if f.starts_with('-') && f.len() > 1 => return Err(format!("unknown option {f}")),
            _ if file.is_none() => file = Some(PathBuf::from(arg)),
            _ => return Err(format!("unexpected argument {arg:?}")),
        }
    }
    let file = file.ok_or("the following arguments are required: file")?;
    Ok(Args { file, opts })
}

fn main() -> ExitCode {
    let args = match parse(std::env::args().skip(1)) {
        Ok(a) => a,
        Err(msg) => return usage(&msg),
    };
    let mut opts = args.opts;
    if opts.protocol == Some(EG2_CAN) {
        // common.py `open_reader` / `byte_protocol`: CAN is chosen by the file
        if !matches!(reader_for(&args.file), Ok(ReaderKind::Candump)) {
            eprintln!(
                "eg2scope: error: {} is read as a byte stream, and CAN is chosen by the file, not \
                 by --protocol: give a CAN capture (candump .log, .asc, .blf, .trc, an eg2scope \
                 .mcap), or -p serial / -p modbus for this one",
                args.file.display()
            );
            return ExitCode::from(EXIT_USAGE);
        }
        opts.protocol = None;
    }
    let mut run = match DecodeRun::open(&args.file, opts) {
        Ok(r) => r,
        Err(e) => {
            eprintln!("eg2scope: error: {e}");
            return ExitCode::from(EXIT_ERROR);
        }
    };
    let stdout = io::stdout();
    let mut out = stdout.lock();
    let mut buf = Vec::with_capacity(BATCH + (BATCH >> 2));
    loop {
        let more = run.next_batch(&mut buf, BATCH);
        if let Err(e) = out.write_all(&buf) {
            if e.kind() == io::ErrorKind::BrokenPipe {
                return ExitCode::SUCCESS; // `| head`: the reader went away; stop quietly
            }
            eprintln!("eg2scope: error: cannot write the output: {e}");
            return ExitCode::from(EXIT_ERROR);
        }
        buf.clear();
        if !more {
            break;
        }
    }
    if let Err(e) = out.flush() {
        if e.kind() != io::ErrorKind::BrokenPipe {
            eprintln!("eg2scope: error: cannot write the output: {e}");
            return ExitCode::from(EXIT_ERROR);
        }
    }
    if let Some(e) = run.failure() {
        eprintln!("eg2scope: error: {e}");
        return ExitCode::from(EXIT_ERROR);
    }
    let path = args.file.display();
    for err in run.errors() {
        eprintln!("eg2scope: {path}: {err}");
    }
    if run.errors().is_empty() {
        ExitCode::SUCCESS
    } else {
        ExitCode::from(EXIT_DAMAGED)
    }
}
