//! The JavaScript client (`clients/js`) and the WebXR example (`examples/webxr`) tested with Node's test runner
//! against this build's `thermode serve`: each folder's packages are installed from its committed
//! `package-lock.json` (`npm ci`, from npm's cache when it has them), then `node --test` runs its suites (the WebXR
//! one in Debian's headless Chromium, `/usr/bin/chromium`). CI installs node, npm and chromium and sets
//! `THERMODE_REQUIRE_NODE_TESTS=1`, so there a missing tool fails the test; elsewhere it is skipped with a message
//! saying what to install.

use std::path::Path;
use std::process::Command;

/// Whether `program --version` runs.
fn runs(program: &str) -> bool {
    Command::new(program)
        .arg("--version")
        .output()
        .is_ok_and(|o| o.status.success())
}

/// Runs `program args` in `dir` with the binary under test in `THERMODE_BIN`; panics with its output on failure.
fn run_in(dir: &Path, program: &str, args: &[&str]) -> String {
    let out = Command::new(program)
        .args(args)
        .current_dir(dir)
        .env("THERMODE_BIN", env!("CARGO_BIN_EXE_thermode"))
        .output()
        .unwrap_or_else(|e| panic!("run {program} in {}: {e}", dir.display()));
    let report = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        out.status.success(),
        "`{program} {}` in {} failed:\n{report}",
        args.join(" "),
        dir.display()
    );
    report
}

/// Installs a folder's packages from its lock file, then runs its test files with `node --test`.
fn install_and_test(dir: &Path, test_files: &[&str]) -> String {
    run_in(dir, "npm", &["ci", "--no-audit", "--no-fund", "--prefer-offline"]);
    let mut args = vec!["--test"];
    args.extend_from_slice(test_files);
    run_in(dir, "node", &args)
}

#[test]
fn the_javascript_client_and_the_webxr_example_pass_their_node_tests() {
    let required = std::env::var("THERMODE_REQUIRE_NODE_TESTS").is_ok_and(|v| v == "1");
    let chromium = Path::new("/usr/bin/chromium").exists();
    if !(runs("node") && runs("npm")) {
        assert!(!required, "THERMODE_REQUIRE_NODE_TESTS=1 but node or npm is missing");
        println!(
            "skipped: install node and npm (apt-get install nodejs npm) to run clients/js and examples/webxr tests"
        );
        return;
    }
    assert!(
        chromium || !required,
        "THERMODE_REQUIRE_NODE_TESTS=1 but /usr/bin/chromium is missing (apt-get install chromium)"
    );
    let repo = Path::new(env!("CARGO_MANIFEST_DIR")).join("../..");
    let client = install_and_test(
        &repo.join("clients/js"),
        &["test/client.test.js", "test/install.test.js", "test/types.test.js"],
    );
    println!("clients/js:\n{client}");
    // The example's test is skipped by itself (and says so) without Chromium, unless it is required.
    let webxr = install_and_test(&repo.join("examples/webxr"), &["test/webxr.test.js"]);
    println!("examples/webxr:\n{webxr}");
}
