//! The README's client commands, run as the README gives them, against `polymap demo`: the
//! demo in the background, then the Python client and the Rust planner client, which find it
//! where they look by default (tcp/127.0.0.1:7447) and print the map.
//!
//! The commands are read from the README (the block after its `tests/readme_clients.rs`
//! marker); `cargo run --release [--example X] --` becomes the binary this test build made,
//! `python3` the virtualenv's python (POLYMAP_PYTHON, from scripts/test.sh).

use std::path::PathBuf;
use std::process::{Command, Stdio};
use std::time::Duration;

mod common;

use common::root;

/// A README command as this test build runs it.
fn command(line: &str) -> (Command, bool) {
    let background = line.ends_with('&');
    let words: Vec<&str> = line.trim_end_matches('&').split_whitespace().collect();
    let bin_dir = PathBuf::from(env!("CARGO_BIN_EXE_polymap")).parent().unwrap().to_path_buf();
    let mut c = match words[..] {
        ["cargo", "run", "--release", "--", ref args @ ..] => {
            let mut c = Command::new(env!("CARGO_BIN_EXE_polymap"));
            c.args(args);
            c
        }
        ["cargo", "run", "--release", "--example", example, ref rest @ ..] => {
            let program = bin_dir.join("examples").join(example);
            assert!(
                program.exists(),
                "{} is not built: `cargo build --examples` first (scripts/test.sh does)",
                program.display()
            );
            let mut c = Command::new(program);
            c.args(rest.iter().skip_while(|w| **w == "--"));
            c
        }
        ["python3", ref args @ ..] => {
            let mut c = Command::new(std::env::var("POLYMAP_PYTHON").expect("POLYMAP_PYTHON (scripts/test.sh)"));
            c.args(args);
            c
        }
        _ => panic!("a README command this test does not know how to run: {line}"),
    };
    c.current_dir(root());
    (c, background)
}

/// A child process killed however the test ends: a failed assert must not leave the demo
/// listening on 7447, where the next run would find the port taken.
struct Running(std::process::Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

#[test]
fn the_readme_s_clients_reach_a_running_demo_and_print_the_map() {
    assert!(
        std::net::TcpListener::bind("127.0.0.1:7447").is_ok(),
        "port 7447 is in use here: the README's clients look for the demo there"
    );
    let lines = common::readme_commands("readme_clients.rs");
    assert_eq!(lines.len(), 3, "{lines:?}");
    let (mut demo_cmd, background) = command(&lines[0]);
    assert!(background && lines[0].contains(" demo"), "the demo runs in the background: {}", lines[0]);
    let mut demo = Running(demo_cmd.stdout(Stdio::piped()).stderr(Stdio::null()).spawn().unwrap());
    // The demo says where clients connect.
    let mut said = String::new();
    {
        use std::io::BufRead;
        let mut out = std::io::BufReader::new(demo.0.stdout.as_mut().unwrap());
        out.read_line(&mut said).unwrap();
    }
    assert!(said.contains("clients connect to tcp/127.0.0.1:7447"), "{said}");
    std::thread::sleep(Duration::from_secs(3));
    let mut outputs = Vec::new();
    for line in &lines[1..] {
        let (mut c, _) = command(line);
        let out = c.output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(out.status.success(), "{line} failed:\n{stdout}\n{}", String::from_utf8_lossy(&out.stderr));
        outputs.push(stdout);
    }
    drop(demo);

    // The Python client: the map's polygons, a foothold on the second tread, RViz markers.
    let v: serde_json::Value = serde_json::from_str(outputs[0].trim()).unwrap();
    let polygons = v["map"]["polygons"].as_array().unwrap();
    assert!(polygons.iter().filter(|p| p["label"] == "tread").count() >= 4, "{}", outputs[0]);
    let tread = polygons.iter().find(|p| p["label"] == "tread").unwrap();
    assert!(tread["vertices"].as_u64().unwrap() >= 4 && tread["convex_pieces"].as_u64().unwrap() >= 1);
    assert!(tread["step"].as_i64().unwrap() >= 1);
    assert_eq!(v["foothold"]["found"], true, "{}", outputs[0]);
    assert_eq!(v["foothold"]["label"], "tread");
    assert_eq!(v["markers"]["ns"], "polymap");
    assert_eq!(v["markers"]["type"], 4, "line strips");

    // The Rust planner client: the map printed polygon by polygon, and the foothold.
    let rust = &outputs[1];
    let count: usize = rust
        .lines()
        .find_map(|l| l.strip_prefix("map: ")?.split_whitespace().next()?.parse().ok())
        .unwrap_or_else(|| panic!("no map printed: {rust}"));
    assert!(count >= 4, "{rust}");
    assert!(rust.lines().filter(|l| l.contains(" tread ")).count() >= 4, "{rust}");
    assert!(rust.contains("foothold: found true (contains true)"), "{rust}");
}
