//! The fuzz targets (polymap::fuzz; cargo-fuzz runs them for long in `fuzz/`), bounded for
//! every test run: each committed input (`fuzz/corpus/<target>/`: the valid seeds, `seed-*`,
//! and small inputs the fuzzer found new paths with, `found-*`; the rest of what cargo-fuzz
//! grows stays out of git), then proptest's mutations of them (bytes flipped, set, cut,
//! repeated, spliced). None may panic; a hang would stop the test.

use std::path::Path;

use proptest::prelude::*;
use proptest::test_runner::{Config, TestRunner};

fn corpus(target: &str) -> Vec<Vec<u8>> {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/corpus").join(target);
    let mut inputs: Vec<_> = std::fs::read_dir(&dir)
        .unwrap_or_else(|e| panic!("{}: {e}", dir.display()))
        .map(|e| e.unwrap().path())
        .filter(|path| {
            path.file_name().is_some_and(|name| {
                let name = name.to_string_lossy();
                name.starts_with("seed-") || name.starts_with("found-")
            })
        })
        .map(|path| std::fs::read(path).unwrap())
        .collect();
    inputs.sort();
    assert!(!inputs.is_empty(), "{target}: an empty corpus");
    inputs
}

#[derive(Clone, Debug)]
enum Mutation {
    Flip { at: usize, bit: u8 },
    Set { at: usize, byte: u8 },
    Cut { at: usize },
    Repeat { at: usize, len: usize },
    Splice { at: usize, from: usize, seed: usize },
}

fn mutation() -> impl Strategy<Value = Mutation> {
    prop_oneof![
        (any::<usize>(), 0..8u8).prop_map(|(at, bit)| Mutation::Flip { at, bit }),
        (any::<usize>(), prop_oneof![Just(0u8), Just(0xff), Just(0x7f), Just(0x80), any::<u8>()])
            .prop_map(|(at, byte)| Mutation::Set { at, byte }),
        any::<usize>().prop_map(|at| Mutation::Cut { at }),
        (any::<usize>(), 1..64usize).prop_map(|(at, len)| Mutation::Repeat { at, len }),
        (any::<usize>(), any::<usize>(), any::<usize>()).prop_map(|(at, from, seed)| Mutation::Splice {
            at,
            from,
            seed
        }),
    ]
}

fn apply(seeds: &[Vec<u8>], seed: usize, mutations: &[Mutation]) -> Vec<u8> {
    let mut data = seeds[seed % seeds.len()].clone();
    for m in mutations {
        let n = data.len().max(1);
        match *m {
            Mutation::Flip { at, bit } if !data.is_empty() => data[at % n] ^= 1 << bit,
            Mutation::Set { at, byte } if !data.is_empty() => data[at % n] = byte,
            Mutation::Cut { at } => data.truncate(at % n),
            Mutation::Repeat { at, len } if !data.is_empty() => {
                let at = at % n;
                let piece: Vec<u8> = data[at..(at + len).min(data.len())].to_vec();
                data.splice(at..at, piece);
            }
            Mutation::Splice { at, from, seed } => {
                let other = &seeds[seed % seeds.len()];
                let tail = &other[from % other.len().max(1)..];
                data.truncate(at % n);
                data.extend_from_slice(tail);
            }
            _ => {}
        }
    }
    data
}

fn fuzz(target: &str, cases: u32) {
    let (_, run) = polymap::fuzz::TARGETS.iter().find(|(name, _)| *name == target).expect("a target");
    let seeds = corpus(target);
    for input in &seeds {
        run(input);
    }
    let mut runner = TestRunner::new(Config { cases, failure_persistence: None, ..Config::default() });
    runner
        .run(&(any::<usize>(), proptest::collection::vec(mutation(), 1..8)), |(seed, mutations)| {
            run(&apply(&seeds, seed, &mutations));
            Ok(())
        })
        .unwrap();
}

#[test]
fn odometry_messages() {
    fuzz("odometry", 20_000);
}

#[test]
fn service_requests() {
    fuzz("service_request", 20_000);
}

#[test]
fn config_files() {
    fuzz("config", 3_000);
}

#[test]
fn sequences() {
    fuzz("sequence", 500);
}

#[test]
fn snapshots() {
    fuzz("snapshot", 1_000);
}

#[test]
fn every_target_has_a_corpus_and_a_cargo_fuzz_target() {
    for (name, _) in polymap::fuzz::TARGETS {
        corpus(name);
        let target = Path::new(env!("CARGO_MANIFEST_DIR")).join("fuzz/fuzz_targets").join(format!("{name}.rs"));
        let text = std::fs::read_to_string(&target).unwrap_or_else(|e| panic!("{}: {e}", target.display()));
        assert!(text.contains(&format!("polymap::fuzz::{name}(")), "{} calls polymap::fuzz::{name}", target.display());
    }
}
