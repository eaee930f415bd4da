//! The malformed corpus (`tests/malformed/`, written by `scripts/malformed_corpus.py`)
//! through the CLI: a file that cannot be drawn gives one clear line naming its fault,
//! with nothing written; a file whose fault spoils one surface only gives a warning
//! naming it, and the rest of the scene is rendered. Never a panic, never a hang. The
//! expected outcome and message of every file are in `tests/malformed/expected.tsv`.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

/// Longer than any file of the corpus takes (a second or two): past it, a hang.
const TIMEOUT: Duration = Duration::from_secs(120);

fn corpus() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../tests/malformed")
}

/// Runs the CLI's quickest render of `file` (the caustic volumes' CPU twin on a 16²
/// irradiance plane) into `png`: (success, stderr).
fn render(file: &Path, png: &Path) -> (bool, String) {
    let mut child = Command::new(env!("CARGO_BIN_EXE_caustics"))
        .args(["render", file.to_str().unwrap(), "--method", "volumes", "--irradiance-plane", "--twin", "--size", "16x16", "--out", png.to_str().unwrap()])
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the caustics binary runs");
    let start = Instant::now();
    loop {
        if let Some(status) = child.try_wait().unwrap() {
            let mut stderr = String::new();
            std::io::Read::read_to_string(&mut child.stderr.take().unwrap(), &mut stderr).unwrap();
            return (status.success(), stderr);
        }
        if start.elapsed() > TIMEOUT {
            let _ = child.kill();
            panic!("{} hangs: no answer in {TIMEOUT:?}", file.display());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

#[test]
fn every_malformed_file_is_one_clear_line_or_a_warning() {
    let expected = std::fs::read_to_string(corpus().join("expected.tsv")).expect("tests/malformed/expected.tsv");
    let out = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("malformed");
    let _ = std::fs::remove_dir_all(&out);
    let mut checked = 0;
    let mut wrong = Vec::new();
    for line in expected.lines().filter(|l| !l.starts_with('#') && !l.trim().is_empty()) {
        let [name, outcome, message] = line.split('\t').collect::<Vec<_>>()[..] else { panic!("expected.tsv: {line:?} is not NAME<TAB>OUTCOME<TAB>MESSAGE") };
        let png = out.join(format!("{name}.png"));
        let (success, stderr) = render(&corpus().join(name), &png);
        let lines: Vec<&str> = stderr.lines().filter(|l| !l.trim().is_empty()).collect();
        let problem = match outcome {
            "fails" if success => Some("rendered".to_string()),
            "fails" if png.exists() => Some("failed but wrote its PNG".to_string()),
            "fails" if lines.len() != 1 || !lines[0].starts_with("caustics: ") => Some(format!("{} lines", lines.len())),
            "renders" | "warns" if !success => Some("failed".to_string()),
            "renders" | "warns" if !png.exists() => Some("wrote no PNG".to_string()),
            "fails" | "renders" | "warns" => None,
            other => panic!("expected.tsv: unknown outcome {other:?}"),
        };
        let problem = problem
            .or_else(|| (!stderr.contains(message)).then(|| format!("no {message:?}")))
            .or_else(|| (stderr.contains("panicked") || stderr.contains("backtrace")).then(|| "a panic".to_string()));
        if let Some(problem) = problem {
            wrong.push(format!("{name} ({outcome}): {problem}; stderr: {}", stderr.trim()));
        }
        checked += 1;
    }
    let files = std::fs::read_dir(corpus()).unwrap().filter(|e| e.as_ref().unwrap().file_name() != "expected.tsv").count();
    assert_eq!(checked, files, "every file of the corpus has a line in expected.tsv");
    assert!(checked >= 30, "the corpus has {checked} files");
    assert!(wrong.is_empty(), "{} of {checked} files:\n{}", wrong.len(), wrong.join("\n"));
}
