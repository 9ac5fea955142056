//! Config: the shipped files load, defaults agree, and every bad value is named.

use std::path::Path;
use std::process::Command;

use polymap::config::{Backend, Config, ConfigError, DepthSourceKind};

fn parse(text: &str) -> Result<Config, ConfigError> {
    Config::parse(text, Path::new("test.toml"))
}

fn error(text: &str) -> ConfigError {
    match parse(text) {
        Ok(c) => panic!("expected an error for {text:?}, got {c:?}"),
        Err(e) => e,
    }
}

#[test]
fn default_toml_documents_exactly_the_defaults() {
    let c = Config::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/default.toml")).unwrap();
    assert_eq!(c, Config::default());
    assert_eq!(c.pipeline.diffusion_time, 60.0 * 0.2, "the reference's 60 explicit steps of 0.2");
    assert!((c.pipeline.diffusion_kappa_m - 134.0 * 0.00025).abs() < 1e-12, "kappa is the reference's 134 units");
}

#[test]
fn default_toml_sets_every_key() {
    // Every field the code knows is written out (and so documented) in default.toml.
    let text = std::fs::read_to_string(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/default.toml")).unwrap();
    let written: toml::Table = toml::from_str(&text).unwrap();
    let full: toml::Table = toml::from_str(&toml::to_string(&Config::default()).unwrap()).unwrap();
    fn keys(t: &toml::Table, prefix: &str, out: &mut Vec<String>) {
        for (k, v) in t {
            match v {
                toml::Value::Table(sub) => keys(sub, &format!("{prefix}{k}."), out),
                _ => out.push(format!("{prefix}{k}")),
            }
        }
    }
    let (mut a, mut b) = (vec![], vec![]);
    keys(&written, "", &mut a);
    keys(&full, "", &mut b);
    a.sort();
    b.sort();
    assert_eq!(a, b);
}

#[test]
fn robot_config_loads() {
    let c = Config::load(Path::new(env!("CARGO_MANIFEST_DIR")).join("config/leju.toml")).unwrap();
    assert_eq!(c.sources.depth.kind, DepthSourceKind::Realsense);
    assert_eq!(c.pipeline.backend, Backend::Gpu);
}

#[test]
fn a_backend_displays_as_its_config_value_reads() {
    for backend in [Backend::Auto, Backend::Gpu, Backend::Cpu] {
        let c = parse(&format!("[pipeline]\nbackend = \"{backend}\"\n")).expect("the displayed name parses");
        assert_eq!(c.pipeline.backend, backend);
    }
    assert_eq!(Backend::Gpu.to_string(), "gpu");
}

#[test]
fn empty_file_is_all_defaults() {
    assert_eq!(parse("").unwrap(), Config::default());
}

#[test]
fn out_of_range_value_names_key_and_reason() {
    let e = error("[pipeline]\ndiffusion_kappa_m = -1.0\n");
    assert_eq!(e.key, "pipeline.diffusion_kappa_m");
    assert!(e.reason.contains("must be within [0.0001, 10]"), "{e}");
    let shown = e.to_string();
    assert!(shown.starts_with("test.toml: pipeline.diffusion_kappa_m:"), "{shown}");
}

#[test]
fn each_impossible_value_is_caught() {
    let cases = [
        ("[pipeline]\ndiffusion_time = -1", "pipeline.diffusion_time", "within"),
        ("[pipeline]\ndiffusion_steps = 1000", "pipeline.diffusion_steps", "within"),
        ("[pipeline]\nnormal_kernel = 4", "pipeline.normal_kernel", "3, 5 or 7"),
        ("[pipeline]\ncanny_low = 0.3\ncanny_high = 0.2", "pipeline.canny_low", "canny_high"),
        ("[pipeline]\nclosing_kernel_px = 12", "pipeline.closing_kernel_px", "odd"),
        ("[pipeline]\nransac_min_inlier_ratio = 1.5", "pipeline.ransac_min_inlier_ratio", "within"),
        ("[pipeline]\nransac_hypotheses = 0", "pipeline.ransac_hypotheses", "within"),
        ("[pipeline]\nmin_polygon_area_m2 = nan", "pipeline.min_polygon_area_m2", "within"),
        ("[map]\ndrift_sigma_m = 0.0", "map.drift_sigma_m", "within"),
        ("[map]\nhorizontal_max_tilt_deg = 70.0", "map.horizontal_max_tilt_deg", "below"),
        ("[sources.extrinsics]\nquat_xyzw = [0.0, 0.0, 0.0, 2.0]", "sources.extrinsics.quat_xyzw", "norm"),
        ("[sources.extrinsics]\nxyz = [0.0, inf, 0.0]", "sources.extrinsics.xyz", "finite"),
        ("[sources.depth]\nfps = 0", "sources.depth.fps", "within"),
        ("[sources.depth]\nsequence = \"\"", "sources.depth.sequence", "sequence directory"),
        ("[ros2]\nnamespace = \"a/*\"", "ros2.namespace", "ROS name"),
        ("[ros2]\nnode = \"my node\"", "ros2.node", "node name"),
    ];
    for (text, key, why) in cases {
        let e = error(text);
        assert_eq!(e.key, key, "for {text:?}: {e}");
        assert!(e.reason.contains(why), "for {text:?}: reason {:?} should mention {why:?}", e.reason);
    }
}

#[test]
fn unknown_key_is_rejected_by_name() {
    let e = error("[pipeline]\ndiffusion_kapa_m = 0.03\n");
    assert!(e.key.starts_with("pipeline"), "{e}");
    assert!(e.reason.contains("unknown field `diffusion_kapa_m`"), "{e}");
    let e = error("[pipelin]\n");
    assert!(e.reason.contains("unknown field `pipelin`"), "{e}");
}

#[test]
fn wrong_type_and_bad_enum_name_their_key() {
    let e = error("[pipeline]\ndiffusion_steps = \"three\"\n");
    assert_eq!(e.key, "pipeline.diffusion_steps", "{e}");
    let e = error("[pipeline]\nbackend = \"tpu\"\n");
    assert_eq!(e.key, "pipeline.backend", "{e}");
    assert!(e.reason.contains("tpu"), "{e}");
    let e = error("[pipeline]\ndiffusion_steps = -3\n");
    assert_eq!(e.key, "pipeline.diffusion_steps", "{e}");
}

#[test]
fn syntax_error_and_missing_file_are_reported() {
    let e = error("[pipeline\n");
    assert_eq!(e.key, "(syntax)");
    let e = Config::load("/nonexistent/polymap.toml").unwrap_err();
    assert_eq!(e.file, Path::new("/nonexistent/polymap.toml"));
}

#[test]
fn cli_stops_on_a_bad_config_naming_file_and_key() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("bad.toml");
    std::fs::write(&file, "[map]\nmerge_height_tolerance_m = -0.05\n").unwrap();
    let out = Command::new(env!("CARGO_BIN_EXE_polymap")).arg("config").arg(&file).output().unwrap();
    assert!(!out.status.success());
    let stderr = String::from_utf8_lossy(&out.stderr);
    assert!(stderr.contains("bad.toml") && stderr.contains("map.merge_height_tolerance_m"), "{stderr}");
}

#[test]
fn the_shipped_zenoh_configs_parse() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("config/zenoh");
    let mut checked = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "json5") {
            polymap::ros2::session::config(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
            checked += 1;
        }
    }
    assert!(checked >= 2, "{checked} configs in {}", dir.display());
}
