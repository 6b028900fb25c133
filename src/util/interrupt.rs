//! Stopping on SIGTERM and SIGINT (what SLURM, systemd, a task graph, `kill`
//! or Ctrl-C send) without leaving processes or half-written files behind.
//!
//! [`install`] starts a thread that waits for either signal. On one it:
//! 1. raises the stop flag ([`requested`], [`check`]): training checkpoints
//!    and returns, sampling and meshing stop between steps or variants, and
//!    the error [`Error::Stopped`] travels up to `main`, which exits 128 +
//!    the signal (130 for SIGINT, 143 for SIGTERM);
//! 2. forwards the signal to every child process started through [`spawn`]
//!    (`run`'s training, sampling and meshing shards), which stop the same
//!    way, and which their parent waits for;
//! 3. gives the process [`GRACE`] (more with children) to end by itself; a
//!    process still running then (inside a long C++ call, say) kills its
//!    children, removes the temporary files its writers have open
//!    ([`Temporary`]) and exits with the same status.
//!
//! Checkpoints, level files and stamps are written atomically, so what is on
//! disk after a stop is whole, and the same command resumes from it.

use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::atomic::{AtomicI32, Ordering};
use std::sync::Mutex;
use std::time::Duration;

use crate::error::{Error, Result};

/// Time a process without children has to stop after the signal.
pub const GRACE: Duration = Duration::from_secs(3);
/// Time a process with children has: theirs plus time to collect them.
pub const GRACE_WITH_CHILDREN: Duration = Duration::from_secs(6);

static SIGNAL: AtomicI32 = AtomicI32::new(0);
static CHILDREN: Mutex<Vec<u32>> = Mutex::new(Vec::new());
static TEMPORARIES: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

/// Starts the signal thread (once per process; `main` calls it first).
pub fn install() -> std::io::Result<()> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    let mut signals = signal_hook::iterator::Signals::new([SIGTERM, SIGINT])?;
    std::thread::Builder::new().name("signals".into()).spawn(move || {
        for sig in signals.forever() {
            let first = SIGNAL.compare_exchange(0, sig, Ordering::SeqCst, Ordering::SeqCst).is_ok();
            let children = forward(sig);
            if first {
                let grace = if children > 0 { GRACE_WITH_CHILDREN } else { GRACE };
                std::thread::spawn(move || {
                    std::thread::sleep(grace);
                    force_exit(sig);
                });
            }
        }
    })?;
    Ok(())
}

/// Sends `sig` to every registered child; how many there were.
fn forward(sig: i32) -> usize {
    let children = CHILDREN.lock().unwrap_or_else(|e| e.into_inner());
    for &pid in children.iter() {
        // SAFETY: kill(2) with a pid this process started and has not reaped.
        unsafe { libc::kill(pid as libc::pid_t, sig) };
    }
    children.len()
}

/// The grace is over: kill what is left, remove the temporary files, exit.
fn force_exit(sig: i32) -> ! {
    forward(libc::SIGKILL);
    for p in TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner()).iter() {
        let _ = std::fs::remove_file(p);
    }
    // Straight to the descriptor: the main thread may hold stderr's lock.
    let line = format!("error: {} (forced after the grace period)\n", Error::Stopped(name(sig)));
    // SAFETY: write(2) of a buffer that outlives the call; _exit ends the
    // process without running atexit handlers or C++ static destructors
    // while other threads may still be inside them.
    unsafe {
        libc::write(2, line.as_ptr().cast(), line.len());
        libc::_exit(128 + sig)
    }
}

/// The signal that asked this process to stop, if any.
pub fn requested() -> Option<i32> {
    match SIGNAL.load(Ordering::SeqCst) {
        0 => None,
        s => Some(s),
    }
}

/// `Err(Error::Stopped)` once a stop was asked for: for loops between steps.
pub fn check() -> Result<()> {
    if let Some(sig) = requested() {
        return Err(Error::Stopped(name(sig)));
    }
    if CANCEL.with(|c| c.borrow().as_ref().is_some_and(|flag| flag.load(Ordering::SeqCst))) {
        return Err(Error::Cancelled);
    }
    Ok(())
}

thread_local! {
    /// This thread's cancel flag, where its work can be cancelled on its
    /// own (a studio job); [`check`] reads it beside the stop signal.
    static CANCEL: std::cell::RefCell<Option<std::sync::Arc<std::sync::atomic::AtomicBool>>> = const { std::cell::RefCell::new(None) };
}

/// Runs `f` on this thread with `flag` as its cancel flag: once the flag is
/// raised, [`check`] (between sampling steps, variants, levels) returns
/// [`Error::Cancelled`].
pub fn cancellable<T>(flag: std::sync::Arc<std::sync::atomic::AtomicBool>, f: impl FnOnce() -> T) -> T {
    let before = CANCEL.with(|c| c.replace(Some(flag)));
    let out = f();
    CANCEL.with(|c| *c.borrow_mut() = before);
    out
}

/// The signal's name (SIGTERM, SIGINT).
pub fn name(sig: i32) -> &'static str {
    match sig {
        libc::SIGTERM => "SIGTERM",
        libc::SIGINT => "SIGINT",
        _ => "a signal",
    }
}

/// The exit status of a process stopped by `sig`: 128 + its number.
pub fn exit_status(sig: i32) -> u8 {
    (128 + sig).clamp(0, 255) as u8
}

/// Starts `command` as a child that stop signals are forwarded to; call
/// [`forget`] once it has been waited for. A stop asked for before it
/// started reaches it too.
pub fn spawn(command: &mut Command) -> std::io::Result<Child> {
    let child = command.spawn()?;
    CHILDREN.lock().unwrap_or_else(|e| e.into_inner()).push(child.id());
    if let Some(sig) = requested() {
        // SAFETY: as in `forward`.
        unsafe { libc::kill(child.id() as libc::pid_t, sig) };
    }
    Ok(child)
}

/// Stops forwarding signals to a child that has been waited for.
pub fn forget(child: &Child) {
    CHILDREN.lock().unwrap_or_else(|e| e.into_inner()).retain(|&p| p != child.id());
}

/// A temporary file removed if the process is stopped by force while it is
/// being written; unregistered when dropped.
pub struct Temporary(PathBuf);

impl Temporary {
    pub fn register(path: &Path) -> Temporary {
        TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner()).push(path.to_path_buf());
        Temporary(path.to_path_buf())
    }
}

impl Drop for Temporary {
    fn drop(&mut self) {
        TEMPORARIES.lock().unwrap_or_else(|e| e.into_inner()).retain(|p| p != &self.0);
    }
}
