//! The Assimp converter: reads FBX, COLLADA and the other formats Assimp
//! knows, and writes them as glTF binary for the glTF reader, in a process
//! of its own (`shapeshifter::io::helper` says why). Not meant to be run by
//! hand: `shapeshifter-assimp IN OUT.glb MEMORY_BYTES` exits 0 when the
//! conversion succeeded, 1 with one line on stderr when it failed cleanly,
//! 2 on bad usage; a crash ends it by a signal.
//!
//! The address space is limited to MEMORY_BYTES before Assimp runs: an
//! allocation past it fails (std::bad_alloc, reported) instead of taking
//! the machine's memory.

use std::ffi::{c_char, c_int, CString};
use std::process::ExitCode;

extern "C" {
    fn shapeshifter_assimp_convert(input: *const c_char, output: *const c_char, message: *mut c_char, message_len: usize) -> c_int;
}

fn main() -> ExitCode {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [input, output, memory] = args.as_slice() else {
        eprintln!("usage: shapeshifter-assimp IN OUT.glb MEMORY_BYTES");
        return ExitCode::from(2);
    };
    let (Ok(i), Ok(o), Ok(memory)) = (CString::new(input.as_str()), CString::new(output.as_str()), memory.parse::<u64>()) else {
        eprintln!("error: {input}: a name holds a NUL byte, or the memory limit is not a number");
        return ExitCode::from(2);
    };
    let limit = libc::rlimit { rlim_cur: memory, rlim_max: memory };
    // SAFETY: a plain system call with a valid struct.
    if unsafe { libc::setrlimit(libc::RLIMIT_AS, &limit) } != 0 {
        eprintln!("error: cannot limit this process's memory ({})", std::io::Error::last_os_error());
        return ExitCode::FAILURE;
    }
    let mut message = vec![0u8; 512];
    // SAFETY: NUL-terminated strings that outlive the call and a writable
    // buffer of `message_len` bytes.
    let code = unsafe { shapeshifter_assimp_convert(i.as_ptr(), o.as_ptr(), message.as_mut_ptr().cast(), message.len()) };
    if code == 0 {
        return ExitCode::SUCCESS;
    }
    let end = message.iter().position(|&b| b == 0).unwrap_or(message.len());
    eprintln!("{}", String::from_utf8_lossy(&message[..end]));
    ExitCode::FAILURE
}
