//! Bounded waits on what a test starts (child processes, daemons, queues): a
//! hang fails the test with a message naming what hung instead of stalling
//! the suite. The bound is far above any normal run, on the slowest and
//! busiest machine the suite runs on, so it measures hangs, never speed.
// Each test crate uses only some of these.
#![allow(dead_code)]

use std::io::Read;
use std::process::{Child, Command, ExitStatus, Output, Stdio};
use std::time::{Duration, Instant};

/// How long anything a test waits on may take before the test calls it hung.
/// The slowest child (a four-cell Slurm grid) takes under 20 s on 2 busy
/// cores, so a machine 10× slower still finishes with a wide margin: only a
/// hang reaches it, and nothing is ever asserted about how long a run took.
pub const HANG_BOUND: Duration = Duration::from_secs(30 * 60);

/// Between two looks at what is awaited.
pub const POLL: Duration = Duration::from_millis(100);

/// Polls `done` until it holds; panics naming `what` once [`HANG_BOUND`] has passed.
pub fn wait_until(what: &str, mut done: impl FnMut() -> bool) {
    let deadline = Instant::now() + HANG_BOUND;
    while !done() {
        assert!(
            Instant::now() < deadline,
            "{what}: still waiting after {} min, so it is taken to hang",
            HANG_BOUND.as_secs() / 60
        );
        std::thread::sleep(POLL);
    }
}

/// Waits for `child` to exit; kills it and panics naming `what` past [`HANG_BOUND`].
pub fn wait_within(child: &mut Child, what: &str) -> ExitStatus {
    let deadline = Instant::now() + HANG_BOUND;
    loop {
        if let Some(status) = child.try_wait().expect("could not poll a child process") {
            return status;
        }
        if Instant::now() >= deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!(
                "{what}: ran past {} min and was killed (a hang?)",
                HANG_BOUND.as_secs() / 60
            );
        }
        std::thread::sleep(POLL);
    }
}

/// `command`'s output, as `Command::output` gives it, within [`HANG_BOUND`].
pub fn output_within(command: &mut Command, what: &str) -> Output {
    let mut child = command
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap_or_else(|e| panic!("{what}: could not start: {e}"));
    // Drained while it runs, so a full pipe never blocks the child.
    let drain = |pipe: Option<Box<dyn Read + Send>>| {
        std::thread::spawn(move || {
            let mut bytes = Vec::new();
            if let Some(mut pipe) = pipe {
                let _ = pipe.read_to_end(&mut bytes);
            }
            bytes
        })
    };
    let stdout = drain(
        child
            .stdout
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let stderr = drain(
        child
            .stderr
            .take()
            .map(|p| Box::new(p) as Box<dyn Read + Send>),
    );
    let status = wait_within(&mut child, what);
    Output {
        status,
        stdout: stdout.join().unwrap_or_default(),
        stderr: stderr.join().unwrap_or_default(),
    }
}
