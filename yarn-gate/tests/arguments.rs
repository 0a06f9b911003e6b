//! Numbers on the command line out of their range are refused before
//! anything runs, with exit code 2 and a message naming the flag and the
//! range, rather than taken into a run that silently does nothing useful
//! (a NaN camera draws an empty frame; a zero duration plots nothing) or
//! that fails later for a reason it does not name.

use std::process::Command;

/// Each command with a flag and a value it must refuse, and words of the
/// range the refusal must name.
const REFUSED: &[(&[&str], &str)] = &[
    (&["drape", "--drop", "nan"], "a finite distance, 0 or more"),
    (&["drape", "--drop", "-5"], "a finite distance, 0 or more"),
    (&["drape", "--orbit", "nan"], "a finite number of degrees"),
    (&["drape", "--elevation", "inf"], "a finite number of degrees"),
    (&["render", "--orbit=-inf"], "a finite number of degrees"),
    (&["render", "--elevation", "NaN"], "a finite number of degrees"),
    (&["bench", "--dead", "2"], "a fraction from 0 to 1"),
    (&["bench", "--dead", "-0.5"], "a fraction from 0 to 1"),
    (&["bench", "--threads", "100000"], "a thread count from 0 (one per core) to 1024"),
    (&["bench", "--repeats", "0"], "a count of runs, 1 or more"),
    (&["pareto", "--repeats", "0"], "a count of runs, 1 or more"),
    (&["pareto", "--substeps", "5,0"], "a count of substeps per tick, 1 or more"),
    (&["pareto", "--duration", "0"], "a finite number of seconds above 0"),
    (&["stress", "--duration", "-1"], "a finite number of seconds above 0"),
];

#[test]
fn a_number_out_of_its_range_is_refused_naming_the_flag() {
    for &(args, range) in REFUSED {
        let output = Command::new(env!("CARGO_BIN_EXE_yarn-gate")).args(args).output().expect("yarn-gate starts");
        let stderr = String::from_utf8_lossy(&output.stderr);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {stderr}");
        let flag = args[1].split('=').next().unwrap_or_default();
        assert!(stderr.contains(flag) && stderr.contains(range), "{args:?}: {stderr}");
    }
}

/// A drop so high that the fall would pass the divergence speed is refused
/// before it runs, naming the highest drop that is not.
#[test]
fn a_drop_too_high_to_land_names_the_highest() {
    let output = Command::new(env!("CARGO_BIN_EXE_yarn-gate"))
        .args(["drape", "--size", "3x3", "--drop", "1e9", "--steps", "1"])
        .output()
        .expect("yarn-gate starts");
    let stderr = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(2), "{stderr}");
    assert!(stderr.contains("drop from below"), "{stderr}");
}
