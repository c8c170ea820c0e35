//! docs/your-own-system.md, run: the tutorial's commands as written, on the
//! shipped pendulum log (which must be what the pendulum below logs), and
//! the served model checked against the pendulum's own physics.

mod common;

use std::io::{Read, Write};
use std::net::TcpStream;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};

use common::copy_dir;
use common::peer::bounded;

/// The pendulum of `examples/pendulum/system.toml`: θ = 0 upright,
/// θ̈ = (g/l)·sin θ − b·θ̇ + u/(m·l²).
const GRAVITY_OVER_LENGTH: f64 = 10.0;
const DAMPING: f64 = 0.1;
const DT: f64 = 0.05;
/// RK4 steps per logged step: the log is the exact flow to ~1e-8.
const SUBSTEPS: usize = 10;
const EPISODES: usize = 40;
const STEPS: usize = 200;

fn acceleration(theta: f64, theta_dot: f64, torque: f64) -> f64 {
    GRAVITY_OVER_LENGTH * theta.sin() - DAMPING * theta_dot + torque
}

/// One logged step of the pendulum from (θ, θ̇) under `torque`.
fn pendulum_step(theta: f64, theta_dot: f64, torque: f64) -> (f64, f64) {
    let h = DT / SUBSTEPS as f64;
    let f = |(x, v): (f64, f64)| (v, acceleration(x, v, torque));
    let mut s = (theta, theta_dot);
    for _ in 0..SUBSTEPS {
        let k1 = f(s);
        let k2 = f((s.0 + 0.5 * h * k1.0, s.1 + 0.5 * h * k1.1));
        let k3 = f((s.0 + 0.5 * h * k2.0, s.1 + 0.5 * h * k2.1));
        let k4 = f((s.0 + h * k3.0, s.1 + h * k3.1));
        s.0 += h / 6.0 * (k1.0 + 2.0 * k2.0 + 2.0 * k3.0 + k4.0);
        s.1 += h / 6.0 * (k1.1 + 2.0 * k2.1 + 2.0 * k3.1 + k4.1);
    }
    s
}

/// SplitMix64 in [0, 1): the log's draws, the same on every machine.
struct Draws(u64);

impl Draws {
    fn uniform(&mut self, low: f64, high: f64) -> f64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^= z >> 31;
        low + (high - low) * (z >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// The shipped log's text: random torques from random starts.
fn pendulum_log() -> String {
    let mut draws = Draws(2026);
    let mut csv = String::from("episode,t,theta,theta_dot,torque,reward,timeout\n");
    for episode in 0..EPISODES {
        let mut theta = draws.uniform(-std::f64::consts::PI, std::f64::consts::PI);
        let mut theta_dot = draws.uniform(-1.0, 1.0);
        for k in 0..=STEPS {
            let torque = draws.uniform(-2.0, 2.0);
            let reward = theta.cos() - 1.0 - 0.1 * theta_dot.powi(2) - 0.001 * torque.powi(2);
            let last = u8::from(k == STEPS);
            csv.push_str(&format!(
                "{episode},{:.6},{theta:.6},{theta_dot:.6},{torque:.6},{reward:.6},{last}\n",
                k as f64 * DT
            ));
            (theta, theta_dot) = pendulum_step(theta, theta_dot, torque);
        }
    }
    csv
}

fn repository() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("..")
}

#[test]
fn the_shipped_log_is_the_pendulum_it_says() {
    let shipped = repository().join("examples/pendulum/log.csv");
    if std::env::var_os("NUNO_WRITE_EXAMPLE_LOG").is_some() {
        std::fs::write(&shipped, pendulum_log()).unwrap();
    }
    let shipped = std::fs::read_to_string(&shipped).unwrap();
    let expected = pendulum_log();
    assert_eq!(shipped.lines().count(), expected.lines().count());
    // Every value to the printed precision (sin may differ in its last bit
    // between libms; the sixth decimal does not move).
    for (row, (a, b)) in shipped.lines().zip(expected.lines()).enumerate().skip(1) {
        for (x, y) in a.split(',').zip(b.split(',')) {
            let (x, y): (f64, f64) = (x.parse().unwrap(), y.parse().unwrap());
            assert!((x - y).abs() <= 2e-6, "row {row}: {a} against {b}");
        }
    }
}

/// The tutorial's commands, one per line of its `sh` blocks before section 4.
fn tutorial_commands() -> Vec<Vec<String>> {
    let doc = std::fs::read_to_string(repository().join("docs/your-own-system.md")).unwrap();
    let mut commands = Vec::new();
    let mut in_sh = false;
    // Section 4 (a simulated system) runs in tests/mujoco_system.rs on tiny budgets.
    for line in doc.lines().take_while(|l| !l.starts_with("## 4.")) {
        match line.trim() {
            "```sh" => in_sh = true,
            "```" => in_sh = false,
            command if in_sh && !command.is_empty() => commands.push(shell_words(command)),
            _ => {}
        }
    }
    commands
}

/// `line` split as a shell splits it, for the single quotes the doc uses.
fn shell_words(line: &str) -> Vec<String> {
    let (mut words, mut word, mut quoted, mut started) = (Vec::new(), String::new(), false, false);
    for c in line.chars() {
        match c {
            '\'' => (quoted, started) = (!quoted, true),
            ' ' if !quoted => {
                if started {
                    words.push(std::mem::take(&mut word));
                }
                started = false;
            }
            c => (word, started) = (word + &c.to_string(), true),
        }
    }
    if started {
        words.push(word);
    }
    words
}

/// `nuno-trainer args`, run in `dir` as the tutorial's reader would, and successful.
fn trainer_in(dir: &Path, args: &[String]) {
    let what = format!("nuno-trainer {}", args.join(" "));
    let out = bounded::output_within(
        Command::new(env!("CARGO_BIN_EXE_nuno-trainer"))
            .args(args)
            .current_dir(dir),
        &what,
    );
    assert!(
        out.status.success(),
        "{what} failed:\n{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
}

/// The server the tutorial starts, stopped when the test ends.
struct Served(Child);

impl Drop for Served {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// `nuno-server`, built beside `nuno-trainer` by `cargo test --workspace`.
fn server_binary() -> PathBuf {
    let binary = Path::new(env!("CARGO_BIN_EXE_nuno-trainer")).with_file_name("nuno-server");
    assert!(
        binary.is_file(),
        "{} is missing: build the workspace (make test does)",
        binary.display()
    );
    binary
}

/// A POST of `body` to `url` (`host:port/path`): the status and the body.
fn post(url: &str, body: &str) -> (u16, serde_json::Value) {
    let (address, path) = url.split_at(url.find('/').unwrap());
    let mut stream = TcpStream::connect(address).unwrap();
    write!(
        stream,
        "POST {path} HTTP/1.1\r\nHost: {address}\r\nContent-Type: application/json\r\n\
         Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
        body.len()
    )
    .unwrap();
    let mut answer = String::new();
    stream.read_to_string(&mut answer).unwrap();
    let status = answer[9..12].parse().unwrap();
    let json = &answer[answer.find("\r\n\r\n").unwrap() + 4..];
    (status, serde_json::from_str(json).unwrap())
}

/// The tutorial's `curl`: its URL and `-d` body, posted.
fn curl(words: &[String]) -> (u16, serde_json::Value) {
    let body = &words[words.iter().position(|w| w == "-d").unwrap() + 1];
    let url = words
        .iter()
        .skip(1)
        .find(|w| w.contains(":") && w.contains('/'))
        .unwrap();
    post(url, body)
}

#[test]
fn the_tutorial_runs_from_a_csv_log_to_a_served_model() {
    let tmp = tempfile::tempdir().unwrap();
    copy_dir(
        &repository().join("examples/pendulum"),
        &tmp.path().join("examples/pendulum"),
    );
    let port = std::net::TcpListener::bind("127.0.0.1:0")
        .unwrap()
        .local_addr()
        .unwrap()
        .port();
    let address = format!("127.0.0.1:{port}");
    let mut served = None;
    let mut answers = Vec::new();
    for words in tutorial_commands() {
        let words: Vec<String> = words
            .iter()
            .map(|w| w.replace("127.0.0.1:8080", &address))
            .collect();
        match words[0].as_str() {
            "nuno-trainer" => trainer_in(tmp.path(), &words[1..]),
            "nuno-server" => {
                let child = Command::new(server_binary())
                    .args(&words[1..])
                    .current_dir(tmp.path())
                    .stdout(Stdio::null())
                    .stderr(Stdio::null())
                    .spawn()
                    .unwrap();
                served = Some(Served(child));
                bounded::wait_until("the tutorial's server to listen", || {
                    TcpStream::connect(&address).is_ok()
                });
            }
            "curl" => answers.push(curl(&words)),
            other => panic!("the tutorial runs `{other}`, which this test does not know"),
        }
    }
    assert!(served.is_some(), "the tutorial starts no server");
    let [(status, step)] = answers.as_slice() else {
        panic!("the tutorial should post one step, got {answers:?}")
    };
    assert_eq!(*status, 200, "{step}");
    check_step_against_the_pendulum(step);
    let run = tmp.path().join("runs/pendulum-policy/metrics.jsonl");
    let records = std::fs::read_to_string(run).unwrap();
    assert!(
        records.lines().all(|r| r.contains("\"in_model\":true")),
        "with no simulator every evaluation is the model's own: {records}"
    );
    let evaluate = post(
        &format!("{address}/v1/evaluate"),
        r#"{"model": "pendulum", "episodes": 1}"#,
    );
    assert_eq!(evaluate.0, 409, "{}", evaluate.1);
    assert_eq!(
        evaluate.1["error"]["code"], "no_simulator",
        "{}",
        evaluate.1
    );
    let refused = post(
        &format!("{address}/v1/models/pendulum/step"),
        r#"{"states": [[0.1, 0.0]], "actions": [[3.0]], "clip": false}"#,
    );
    assert_eq!(refused.0, 422, "{}", refused.1);
    // Cost terms name the file's observations: `theta` is observation 0.
    let score = |observation: &str| {
        post(
            &format!("{address}/v1/models/pendulum/score"),
            &format!(
                r#"{{"states": [[0.1, 0.0]], "shared_actions": [[[0.5], [0.5]]], "horizon": 2,
                    "noise_scale": 0, "cost": {{"terms": [{{"observation": {observation},
                    "target": 0.0, "weight": 2.0}}], "replace_reward": true}}}}"#
            ),
        )
    };
    let (by_name, by_index) = (score(r#""theta""#), score("0"));
    assert_eq!((by_name.0, by_index.0), (200, 200), "{}", by_name.1);
    let cost = &by_name.1["scores"][0][0]["mean_return"];
    assert!(cost.as_f64().unwrap() < 0.0, "{}", by_name.1);
    assert_eq!(cost, &by_index.1["scores"][0][0]["mean_return"]);
    let unknown = score(r#""phi""#);
    assert_eq!(unknown.0, 422, "{}", unknown.1);
    assert!(
        unknown
            .1
            .to_string()
            .contains("no observation `phi` (the model's are theta, theta_dot)"),
        "{}",
        unknown.1
    );
}

/// The tutorial's step: the torque of 3 clipped to 2, the mean next state
/// near the pendulum's own step (far nearer than "nothing moves"), rewards
/// by the file's expression.
fn check_step_against_the_pendulum(step: &serde_json::Value) {
    assert_eq!(step["clipped_rows"], 1, "{step}");
    let starts = [((0.1, 0.0), 2.0), ((3.0, -1.0), -0.5)];
    let (mut model_error, mut still_error) = (0.0, 0.0);
    for (b, ((theta, theta_dot), torque)) in starts.into_iter().enumerate() {
        let truth = pendulum_step(theta, theta_dot, torque);
        let mean = &step["mean"][b];
        let (m0, m1) = (mean[0].as_f64().unwrap(), mean[1].as_f64().unwrap());
        model_error += (m0 - truth.0).powi(2) + (m1 - truth.1).powi(2);
        still_error += (theta - truth.0).powi(2) + (theta_dot - truth.1).powi(2);
        for p in 0..4 {
            let next = &step["next_states"][b][p];
            let reward = step["rewards"][b][p].as_f64().unwrap();
            // The expression reads the state before the step and the action, clipped.
            let expected = theta.cos() - 1.0 - 0.1 * theta_dot.powi(2) - 0.001 * torque.powi(2);
            assert!(
                (reward - expected).abs() < 1e-5,
                "{reward} against {expected}: {next}"
            );
        }
    }
    assert!(
        model_error < 0.1 * still_error,
        "the model's mean step is off by {model_error:.4} (squared), standing still by {still_error:.4}"
    );
}
