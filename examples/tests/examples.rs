//! Every example runs, briefly (`YARNIFY_EXAMPLE_QUICK`), and says or
//! writes what it promises, so none can rot. `cargo test` builds the
//! examples before it runs this; they sit in `target/<profile>/examples/`.

use std::path::PathBuf;
use std::process::{Command, Output};

fn run(name: &str, args: &[&str]) -> Output {
    // This test runs from target/<profile>/deps/.
    let exe = std::env::current_exe().expect("the test's own path");
    let profile = exe.parent().and_then(|deps| deps.parent()).expect("target/<profile>/deps/");
    let binary: PathBuf = profile.join("examples").join(name);
    assert!(binary.exists(), "{} was not built", binary.display());
    Command::new(binary).args(args).env("YARNIFY_EXAMPLE_QUICK", "1").output().expect("the example starts")
}

fn stdout(output: &Output) -> String {
    assert!(output.status.success(), "{}", String::from_utf8_lossy(&output.stderr));
    String::from_utf8_lossy(&output.stdout).into_owned()
}

/// GPU examples skip, counted, only when the example found no adapter
/// ([`yarn_backend_wgpu::testing`]).
fn gpu_missing(output: &Output) -> bool {
    let stderr = String::from_utf8_lossy(&output.stderr);
    let missing = !output.status.success() && stderr.contains("no GPU adapter found");
    if missing {
        yarn_backend_wgpu::testing::skip(&stderr);
    }
    missing
}

fn temp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("yarnify-example-{}-{name}", std::process::id()))
}

#[test]
fn serial_prints_the_energy_falling() {
    let out = stdout(&run("serial", &[]));
    // 16x16 interlooped: 16 rows of 16 loops of 24 nodes, a far sinker a
    // row and 4 nodes in each of 15 turns; 4 crossings a stitch above row 0.
    assert!(out.starts_with("6220 nodes, 960 contacts"), "{out}");
    let totals: Vec<f64> =
        out.lines().filter_map(|l| l.split("total").nth(1)?.split_whitespace().next()?.parse().ok()).collect();
    assert_eq!(totals.len(), 7, "{out}");
    assert!(totals.last() < totals.first(), "{totals:?}");
}

#[test]
fn rayon_times_a_large_patch() {
    let out = stdout(&run("rayon", &[]));
    // 64x64 interlooped: 64 × (64 × 24 + 1) + 63 × 4 nodes.
    assert!(out.contains("of 98620 nodes on") && out.contains("ns per node-substep"), "{out}");
}

#[test]
fn wgpu_runs_both_modes() {
    let output = run("wgpu", &[]);
    if gpu_missing(&output) {
        return;
    }
    let out = stdout(&output);
    assert!(out.contains("wgpu-gather") && out.contains("wgpu-fixed") && out.contains("largest gap"), "{out}");
}

#[test]
fn render_writes_a_png() {
    let path = temp("render.png");
    let output = run("render", &[path.to_str().unwrap()]);
    if gpu_missing(&output) {
        return;
    }
    assert!(stdout(&output).contains("of the frame is yarn"));
    assert_eq!(&std::fs::read(&path).unwrap()[..8], b"\x89PNG\r\n\x1a\n");
    std::fs::remove_file(path).unwrap();
}

#[test]
fn drape_pins_a_row_and_writes_an_obj() {
    let path = temp("drape.obj");
    let out = stdout(&run("drape", &[path.to_str().unwrap()]));
    assert!(out.contains("pinned 481 nodes of 7756"), "{out}");
    let drop: f64 = out.split("hangs ").nth(1).unwrap().split_whitespace().next().unwrap().parse().unwrap();
    assert!(drop > 0.0, "gravity must pull the fabric down: {out}");
    let mesh = std::fs::read_to_string(&path).unwrap();
    assert_eq!(mesh.lines().filter(|l| l.starts_with("v ")).count(), 7756 * 7);
    std::fs::remove_file(path).unwrap();
}

/// Both problems print a dynamics row and three statics rows, and the last
/// solve gets at least as low as the dynamics did.
#[test]
fn statics_gets_as_low_as_the_dynamics() {
    let out = stdout(&run("statics", &[]));
    let energy = |line: &str| -> f64 { line[46..].split_whitespace().nth(1).unwrap().parse().unwrap() };
    for problem in ["4x4 hung", "16x16 free"] {
        let rows: Vec<&str> = out.lines().filter(|l| l.starts_with(problem)).collect();
        assert_eq!(rows.len(), 4, "{out}");
        assert!(rows[0].contains("dynamics") && rows[3].contains("to that energy"), "{out}");
        assert!(energy(rows[3]) <= energy(rows[0]), "{out}");
    }
}
