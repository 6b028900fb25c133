//! The .vdb probe: parses a file's grids in a process of its own, so a
//! reader that crashes on a damaged file takes down only this process
//! (`shapeshifter::io::probe` says why and how it is used). Not meant to be
//! run by hand: `shapeshifter-vdb-probe FILE.vdb [GRID...]` exits 0 when the
//! parse succeeds, 1 with OpenVDB's message (one line on stderr, which the
//! caller puts in its own error) when it fails cleanly, 2 on bad usage; a
//! crash ends it by a signal.
//!
//! It calls the C++ reader directly (cpp/vdb_guard.cpp), not through the
//! library crate, so that it starts in milliseconds: the library links
//! libtorch, whose start-up costs about a quarter of a second.

use std::ffi::{c_char, c_int, CString};
use std::process::ExitCode;

extern "C" {
    fn shapeshifter_probe_vdb(path: *const c_char, names: *const *const c_char, count: usize, message: *mut c_char, message_len: usize) -> c_int;
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let Some((file, names)) = args.split_first() else {
        eprintln!("usage: shapeshifter-vdb-probe FILE.vdb [GRID...]");
        return ExitCode::from(2);
    };
    let (Ok(path), Ok(names)) = (CString::new(file.as_str()), names.iter().map(|n| CString::new(n.as_str())).collect::<Result<Vec<_>, _>>()) else {
        eprintln!("error: {file}: a name holds a NUL byte");
        return ExitCode::from(2);
    };
    let pointers: Vec<*const c_char> = names.iter().map(|n| n.as_ptr()).collect();
    let mut message = vec![0u8; 512];
    // SAFETY: NUL-terminated strings that outlive the call, a pointer array
    // of `count` entries, and a writable buffer of `message_len` bytes.
    let code = unsafe { shapeshifter_probe_vdb(path.as_ptr(), pointers.as_ptr(), pointers.len(), message.as_mut_ptr().cast(), message.len()) };
    if code == 0 {
        return ExitCode::SUCCESS;
    }
    let end = message.iter().position(|&b| b == 0).unwrap_or(message.len());
    eprintln!("{}", String::from_utf8_lossy(&message[..end]));
    ExitCode::FAILURE
}
