//! The Python packages (`python/thermode-client`, `python/psychopy-thermode`) tested with pytest against this
//! build's `thermode serve`, and `serve --lsl` judged by a pylsl inlet (`python/lsl`, which also needs `pylsl`). They
//! need `websockets` and `pytest`; CI installs both (and pylsl) and sets
//! `THERMODE_REQUIRE_PYTHON_TESTS=1`, so there a missing module fails the test. Elsewhere it is skipped with a
//! message saying how to run it.

use std::path::Path;
use std::process::Command;

#[test]
fn the_python_client_and_the_psychopy_plugin_pass_their_tests() {
    let required = std::env::var("THERMODE_REQUIRE_PYTHON_TESTS").is_ok_and(|v| v == "1");
    let ready = Command::new("python3")
        .args(["-c", "import websockets, pytest"])
        .output()
        .is_ok_and(|o| o.status.success());
    if !ready {
        assert!(
            !required,
            "THERMODE_REQUIRE_PYTHON_TESTS=1 but python3 lacks websockets or pytest"
        );
        println!("skipped: `python3 -m pip install websockets pytest` to run the Python packages' tests");
        return;
    }
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let out = Command::new("python3")
        .args(["-m", "pytest", "-q", "-p", "no:cacheprovider", "python"])
        .current_dir(&repo)
        .env("THERMODE_BIN", env!("CARGO_BIN_EXE_thermode"))
        .output()
        .unwrap_or_else(|e| panic!("run pytest: {e}"));
    let report = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    println!("{report}");
    assert!(out.status.success(), "pytest failed:\n{report}");
}
