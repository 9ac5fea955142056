//! The README's commands, run as the README gives them: the Quick start's demo, which leaves
//! `out/map.json` and `out/map.png`; and the client commands against `polymap demo`: the
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

/// The demos of this file one at a time: each wants the README's port, 7447.
static DEMO: std::sync::Mutex<()> = std::sync::Mutex::new(());

#[test]
fn the_readme_s_clients_reach_a_running_demo_and_print_the_map() {
    let _one_demo = DEMO.lock().unwrap_or_else(|e| e.into_inner());
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

/// The Quick start's first command, as written, in a folder of its own (holding the bundled
/// frames it replays): it ends with the map in `out/map.json` and its top-down picture, truth
/// outlines in yellow, in `out/map.png`.
#[test]
fn the_quick_start_demo_leaves_the_map_and_its_picture_in_out() {
    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let quick = &readme[readme.find("## Quick start").expect("a Quick start")..];
    let block = &quick[quick.find("```sh\n").unwrap() + 6..];
    let line = block.lines().next().unwrap().trim();
    assert_eq!(line, "cargo run --release -- demo", "the Quick start's first command");
    let _one_demo = DEMO.lock().unwrap_or_else(|e| e.into_inner());
    let dir = tempfile::tempdir().unwrap();
    std::os::unix::fs::symlink(root().join("mock_frames"), dir.path().join("mock_frames")).unwrap();
    let (mut demo, _) = command(line);
    let out = demo.current_dir(dir.path()).output().unwrap();
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{line}: {stdout}\n{}", String::from_utf8_lossy(&out.stderr));
    let map: polymap::map::MapSnapshot =
        serde_json::from_str(&std::fs::read_to_string(dir.path().join("out/map.json")).unwrap()).unwrap();
    let treads = map.polygons.iter().filter(|p| p.label == polymap::map::Label::Tread).count();
    assert!(treads >= 4, "{treads} treads in out/map.json: {stdout}");
    let picture = image::open(dir.path().join("out/map.png")).unwrap().to_rgb8();
    assert!(picture.width() >= 200 && picture.height() >= 200, "{}x{}", picture.width(), picture.height());
    let yellow = picture.pixels().filter(|p| p[0] > 200 && p[1] > 200 && p[2] < 80).count();
    assert!(yellow >= 200, "{yellow} yellow pixels: the truth's outlines are drawn");
}

/// The README's offline commands as a user runs them on the bundled stairs: `inspect` with
/// its previews, `extract` of one frame, `eval` of every frame, `replay` with `--out` and
/// `--render`, and `eval --map` of that map; and every command the README lists has a `--help`.
#[test]
fn the_readme_s_offline_commands_do_what_it_says() {
    let dir = tempfile::tempdir().unwrap();
    let seq = root().join("mock_frames/straight_320");
    let run = |args: &[&std::ffi::OsStr]| -> String {
        let out = Command::new(env!("CARGO_BIN_EXE_polymap")).args(args).output().unwrap();
        let stdout = String::from_utf8_lossy(&out.stdout).into_owned();
        assert!(out.status.success(), "polymap {args:?}: {stdout}\n{}", String::from_utf8_lossy(&out.stderr));
        stdout
    };
    let at = |name: &str| dir.path().join(name);
    let json = |path: &std::path::Path| -> serde_json::Value {
        serde_json::from_str(&std::fs::read_to_string(path).unwrap()).unwrap()
    };
    let (seq_arg, cpu) = (seq.as_os_str(), ["--backend".as_ref(), "cpu".as_ref()]);

    let said = run(&["inspect".as_ref(), seq_arg, "--preview".as_ref(), at("preview").as_os_str()]);
    assert!(said.contains("30 frames, 320x240") && said.contains("labels: yes"), "{said}");
    assert_eq!(std::fs::read_dir(at("preview")).unwrap().count(), 30, "a preview a frame");

    run(&[
        &["extract".as_ref(), seq_arg, "--frame".as_ref(), "5".as_ref(), "--out".as_ref(), at("f5.json").as_os_str()],
        &cpu[..],
    ]
    .concat());
    let frame = json(&at("f5.json"));
    assert_eq!(frame["frame"], "camera", "its polygons in the camera frame without --world");
    assert!(frame["polygons"].as_array().unwrap().len() >= 4, "{frame}");

    let eval: serde_json::Value =
        serde_json::from_str(&run(&[&["eval".as_ref(), seq_arg, "--json".as_ref()], &cpu[..]].concat())).unwrap();
    let summary = &eval["summary"];
    assert_eq!(eval["treads"].as_array().unwrap().len() as u64, summary["treads_in_view"].as_u64().unwrap());
    assert!(
        summary["treads_in_view"].as_u64().unwrap() >= 50 && summary["iou_mean"].as_f64().unwrap() >= 0.9,
        "{summary}"
    );

    let (map, picture) = (at("map.json"), at("map.png"));
    run(&[
        &["replay".as_ref(), seq_arg, "--out".as_ref(), map.as_os_str(), "--render".as_ref(), picture.as_os_str()],
        &cpu[..],
    ]
    .concat());
    let snapshot: polymap::map::MapSnapshot = serde_json::from_value(json(&map)).unwrap();
    assert!(snapshot.polygons.iter().filter(|p| p.label == polymap::map::Label::Tread).count() >= 6);
    let picture = image::open(&picture).unwrap().to_rgb8();
    assert!(picture.pixels().filter(|p| p[0] > 200 && p[1] > 200 && p[2] < 80).count() >= 200, "truth outlines drawn");

    let scored: serde_json::Value =
        serde_json::from_str(&run(&["eval".as_ref(), seq_arg, "--map".as_ref(), map.as_os_str(), "--json".as_ref()]))
            .unwrap();
    let s = &scored["summary"];
    assert!(s["iou_mean"].as_f64().unwrap() >= 0.98 && s["height_error_max_mm"].as_f64().unwrap() < 1.0, "{s}");

    let readme = std::fs::read_to_string(root().join("README.md")).unwrap();
    let commands = &readme[readme.find("## Commands").unwrap()..];
    let commands = &commands[..commands.find("\n## ").unwrap()];
    let mut listed: Vec<&str> =
        commands.lines().filter_map(|l| l.strip_prefix("polymap ")?.split_whitespace().next()).collect();
    listed.dedup();
    assert!(listed.len() >= 12, "{listed:?}");
    for command in listed {
        run(&[command.as_ref(), "--help".as_ref()]);
    }
}
