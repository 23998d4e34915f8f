//! The global allocator: mimalloc.
//!
//! Every record owns a few small heap buffers (raw bytes, fields, summary, notes) that live for
//! one batch; with glibc's malloc about 40% of a decoder's instructions went to malloc/free
//! (callgrind, 100k serial frames). mimalloc's thread-local free lists make them cheap. It
//! applies to the command-line driver and to the Python extension's own allocations alike.

#[global_allocator]
static GLOBAL: mimalloc::MiMalloc = mimalloc::MiMalloc;
