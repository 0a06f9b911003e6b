//! `--pattern` and `--preset` on the command line: a chart reaches every
//! command that builds a patch, its errors name where they are, the paper's
//! arch refuses purl, and bench counts stitches beside nodes. Every run
//! here is small or fails before it simulates anything.

use std::path::PathBuf;
use std::process::{Command, Output};

/// The message of a chart file with a bad letter at chart row 2 (text line
/// 2), column 2: what [`bad_chart`] holds.
const BAD_AT: &str = "chart row 2 (line 2), column 2: 'x' is not a stitch";

/// The start of the arch's refusal of a purl stitch.
const ARCH_PURL: &str = "the paper's arch knits only knit stitches";

fn yarn_gate(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_yarn-gate")).args(args).output().expect("yarn-gate starts")
}

fn stderr(output: &Output) -> String {
    String::from_utf8_lossy(&output.stderr).into_owned()
}

/// A chart file of this test's own, removed when dropped.
struct ChartFile(PathBuf);

impl ChartFile {
    fn new(name: &str, text: &str) -> Self {
        let path = std::env::temp_dir().join(format!("yarnify-{name}-{}.txt", std::process::id()));
        std::fs::write(&path, text).expect("the temp folder is writable");
        Self(path)
    }

    fn path(&self) -> &str {
        self.0.to_str().expect("a UTF-8 temp path")
    }
}

impl Drop for ChartFile {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

fn bad_chart() -> ChartFile {
    ChartFile::new("bad-chart", "kkk\nkxk\nkkk\n")
}

/// Every command that builds a patch, with arguments small enough to run.
fn commands(out: &str) -> [Vec<&str>; 4] {
    [
        vec!["check", "--steps", "10"],
        vec!["render", "--steps", "10", "--image", "32x24", "--backend", "serial-f32", "--out", out],
        vec!["bench", "--sizes", "3", "--repeats", "1", "--backend", "serial-f32"],
        vec![
            "pareto",
            "--duration",
            "0.02",
            "--substeps",
            "5",
            "--repeats",
            "1",
            "--backend",
            "serial-f32",
            "--out",
            out,
        ],
    ]
}

#[test]
fn a_bad_chart_file_is_an_error_naming_its_row_and_column_in_every_command() {
    let chart = bad_chart();
    let out = std::env::temp_dir().join(format!("yarnify-never-written-{}", std::process::id()));
    for mut args in commands(out.to_str().unwrap()) {
        args.extend(["--pattern", chart.path()]);
        let output = yarn_gate(&args);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {}", stderr(&output));
        assert!(stderr(&output).contains(BAD_AT), "{args:?}: {}", stderr(&output));
    }
    assert!(!out.exists(), "nothing was written");
    let missing = yarn_gate(&["check", "--pattern", "/nonexistent/yarnify/chart.txt"]);
    assert_eq!(missing.status.code(), Some(2));
}

#[test]
fn an_unknown_pattern_lists_every_name_and_says_a_chart_file_will_do() {
    for command in ["check", "render", "bench", "pareto"] {
        let output = yarn_gate(&[command, "--pattern", "moss-stitch"]);
        assert_eq!(output.status.code(), Some(2), "{command}");
        let message = stderr(&output);
        for name in ["stockinette", "reverse-stockinette", "garter", "rib-1x1", "rib-2x2", "seed"] {
            assert!(message.contains(name), "{command}: {name} missing from {message}");
        }
        assert!(message.contains("moss-stitch") && message.contains("chart file"), "{command}: {message}");
    }
}

/// The paper's arch has no purl: a named pattern or a chart file with one
/// fails, typed, before anything runs, in every command.
#[test]
fn the_paper_preset_refuses_a_purl_stitch_with_the_arch_error() {
    let output = yarn_gate(&["check", "--preset", "paper", "--pattern", "rib-1x1", "--size", "4x4"]);
    assert_eq!(output.status.code(), Some(2), "{}", stderr(&output));
    assert!(stderr(&output).contains(ARCH_PURL) && stderr(&output).contains("stitch (1, 0) is a purl"));
    // Knit below, one purl at column 3 of the top row.
    let chart = ChartFile::new("one-purl", "kkp\nkkk\nkkk\n");
    let output = yarn_gate(&["check", "--preset", "paper", "--pattern", chart.path(), "--json"]);
    assert_eq!(output.status.code(), Some(2));
    assert!(stderr(&output).contains("stitch (2, 2) is a purl"), "{}", stderr(&output));
    assert!(output.stdout.is_empty(), "no report for a gate that never ran");
    let out = std::env::temp_dir().join(format!("yarnify-never-written-purl-{}", std::process::id()));
    for mut args in commands(out.to_str().unwrap()) {
        args.extend(["--preset", "paper", "--pattern", "seed"]);
        let output = yarn_gate(&args);
        assert_eq!(output.status.code(), Some(2), "{args:?}: {}", stderr(&output));
        assert!(stderr(&output).contains(ARCH_PURL), "{args:?}: {}", stderr(&output));
    }
    // The default geometry knits the same charts.
    let output =
        yarn_gate(&["bench", "--pattern", "seed", "--sizes", "3", "--repeats", "1", "--backend", "serial-f32"]);
    assert!(output.status.success(), "{}", stderr(&output));
}

/// An all-knit chart file is stockinette at its own size: the paper's
/// gate on it prints, byte for byte, what it prints for that size, and
/// --size is unused.
#[test]
fn the_paper_gate_on_an_all_knit_chart_file_runs_at_the_chart_size() {
    let chart = ChartFile::new("all-knit", "# 5 wide, 4 rows\nk k k k k\nKKKKK\n\nkkkkk\nkkkkk  # cast-on\n");
    let quick = ["--steps", "600", "--backend", "serial-f32", "--json"];
    let from_file =
        yarn_gate(&[&["check", "--preset", "paper", "--pattern", chart.path(), "--size", "9x9"], &quick[..]].concat());
    let sized = yarn_gate(&[&["check", "--preset", "paper", "--size", "5x4"], &quick[..]].concat());
    assert_eq!(from_file.status.code(), sized.status.code(), "{}", stderr(&from_file));
    assert!(matches!(from_file.status.code(), Some(0 | 1)), "it ran: {}", stderr(&from_file));
    assert_eq!(String::from_utf8_lossy(&from_file.stdout), String::from_utf8_lossy(&sized.stdout));
    let json: serde_json::Value = serde_json::from_slice(&from_file.stdout).unwrap();
    assert_eq!((json["size"].as_str(), json["nodes"].as_u64()), (Some("5x4"), Some(160)));
}

/// Each bench row counts its stitches, and its cost per stitch is its cost
/// per node times the nodes a stitch has, for either preset; a chart file
/// sets the one size benched.
#[test]
fn bench_rows_carry_stitches_and_their_cost_per_stitch() {
    let chart = ChartFile::new("bench", "kkk\nkkk\n");
    let runs = [
        (vec!["--pattern", "rib-1x1", "--sizes", "3"], "3x3", 9),
        (vec!["--preset", "paper", "--pattern", chart.path(), "--sizes", "7,8"], "3x2", 6),
    ];
    for (args, size, stitches) in runs {
        let output =
            yarn_gate(&[&["bench", "--repeats", "1", "--backend", "serial-f32", "--json"], &args[..]].concat());
        assert!(output.status.success(), "{args:?}: {}", stderr(&output));
        let rows: Vec<serde_json::Value> = serde_json::from_slice(&output.stdout).expect("a JSON array");
        let [row] = rows.as_slice() else { panic!("{args:?}: one size, one row: {rows:?}") };
        assert_eq!((row["size"].as_str(), row["stitches"].as_u64()), (Some(size), Some(stitches)), "{row}");
        let figure = |key: &str| row[key].as_f64().unwrap_or_else(|| panic!("{key} missing from {row}"));
        let expected = figure("ns_per_node_substep") * figure("nodes") / figure("stitches");
        assert!(expected > 0.0 && (figure("ns_per_stitch_substep") - expected).abs() <= 1e-9 * expected, "{row}");
    }
    let output = yarn_gate(&[
        "bench",
        "--preset",
        "paper",
        "--pattern",
        chart.path(),
        "--repeats",
        "1",
        "--backend",
        "serial-f32",
    ]);
    let table = String::from_utf8_lossy(&output.stdout);
    assert!(
        table.contains("stitches") && table.contains("ns/stitch-step") && table.contains("ns/node-step"),
        "{table}"
    );
}
