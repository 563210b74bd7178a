//! `simulate` and `render` with `--out` ending in `.arrow`, `.feather` or `.parquet`: the file read back (with
//! `thermode_table::read`) has the CSV's columns in its order and, row by row, the value its CSV field holds:
//! floats bit for bit (the exact CSV reads back as the same `f64`), integers, text, null for an empty field. The
//! curve reader of `lab analyze --curves` gives the same analysis from either file; `--precision` with a columnar
//! output is refused before any work.

use std::path::Path;

use thermode_table::{Table, Values};

use super::{expect_error, expect_success};

/// The CSV at `path`: header and rows of fields.
fn read_csv(path: &Path) -> (Vec<String>, Vec<Vec<String>>) {
    let text = std::fs::read_to_string(path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let mut lines = text.lines();
    let header = lines
        .next()
        .unwrap_or_default()
        .split(',')
        .map(str::to_string)
        .collect();
    let rows = lines.map(|l| l.split(',').map(str::to_string).collect()).collect();
    (header, rows)
}

/// Every value of `table` against the CSV field of the same row and column.
fn assert_same_as_csv(table: &Table, csv: &Path, what: &str) {
    let (header, rows) = read_csv(csv);
    let names: Vec<&str> = table.columns.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(names, header, "{what}: the CSV's columns in its order");
    assert_eq!(table.rows(), rows.len(), "{what}: the CSV's rows");
    for (column, (name, values)) in table.columns.iter().enumerate() {
        for (row, fields) in rows.iter().enumerate() {
            let field = fields[column].as_str();
            let same = match values {
                Values::F64(v) => {
                    let csv_value: f64 = field
                        .parse()
                        .unwrap_or_else(|e| panic!("{what}: {name} {field:?}: {e}"));
                    csv_value.to_bits() == v[row].to_bits() || (csv_value.is_nan() && v[row].is_nan())
                }
                Values::I64(v) => v[row].map_or(String::new(), |x| x.to_string()) == field,
                Values::F64Null(v) => match v[row] {
                    Some(x) => field.parse::<f64>().is_ok_and(|c| c.to_bits() == x.to_bits()),
                    None => field.is_empty(),
                },
                Values::Text(v) => v[row].as_deref().unwrap_or("") == field,
                Values::Repeat { .. } => panic!("{what}: {name}: read back as text, never as a repeat"),
            };
            assert!(
                same,
                "{what}: row {row} column {name}: CSV {field:?}, file {}",
                values.field(row)
            );
        }
    }
}

/// The simulation's 10 001 rows a material cross the pieces its writer thread takes (8 192 rows) and the two
/// materials' runs meet inside the file.
#[test]
fn simulate_and_render_write_arrow_and_parquet_with_the_csvs_columns_and_exact_values() {
    let dir = tempfile::tempdir().expect("temp dir");
    let path = |name: &str| dir.path().join(name).display().to_string();
    let simulate = [
        "simulate",
        "--material",
        "aluminium",
        "--material",
        "wood",
        "--duration",
        "10",
        "--dt",
        "0.001",
    ];
    let render = [
        "render",
        "--material",
        "aluminium",
        "--controller",
        "both",
        "--duration",
        "3",
        "--pre-contact",
        "0.5",
    ];
    for (command, args) in [("simulate", &simulate[..]), ("render", &render[..])] {
        let csv = path(&format!("{command}.csv"));
        expect_success(&[args, &["--out", &csv]].concat());
        for extension in ["arrow", "feather", "parquet"] {
            let file = path(&format!("{command}.{extension}"));
            expect_success(&[args, &["--out", &file]].concat());
            let table = thermode_table::read(Path::new(&file)).unwrap_or_else(|e| panic!("{file}: {e}"));
            assert_same_as_csv(&table, Path::new(&csv), &format!("{command} .{extension}"));
        }
        let analysis = |file: &str| {
            let curves = thermode_lab::analysis::analyze_curves(&[file.into()]).unwrap_or_else(|e| panic!("{e}"));
            format!("{:?} {:?}", curves.temperature_columns, curves.materials)
        };
        if command == "render" {
            let from_csv = analysis(&csv);
            for extension in ["arrow", "parquet"] {
                let from_file = analysis(&path(&format!("render.{extension}")));
                assert_eq!(
                    from_file, from_csv,
                    "lab analyze --curves from .{extension} and from the CSV"
                );
            }
        }
    }
    expect_error(
        &[&simulate[..], &["--out", &path("rounded.parquet"), "--precision", "3"]].concat(),
        "stores every number exactly",
    );
    assert!(!Path::new(&path("rounded.parquet")).exists(), "refused before any work");
}

/// POSTs `body` to `/api/command` of the daemon on `port`; the response's text.
#[cfg(unix)]
fn post_command(port: u16, body: &str) -> String {
    use std::io::{Read, Write};
    let mut stream = std::net::TcpStream::connect(("127.0.0.1", port)).unwrap_or_else(|e| panic!("connect: {e}"));
    let request = format!(
        "POST /api/command HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nConnection: close\r\nContent-Type: \
         application/json\r\nContent-Length: {}\r\n\r\n{body}",
        body.len()
    );
    stream
        .write_all(request.as_bytes())
        .unwrap_or_else(|e| panic!("send: {e}"));
    let mut response = String::new();
    let _ = stream.read_to_string(&mut response);
    response
}

#[cfg(unix)]
#[test]
fn serve_record_to_arrow_or_parquet_also_writes_the_sessions_csv_values_there() {
    for extension in ["arrow", "parquet"] {
        let dir = tempfile::tempdir().expect("temp dir");
        let file = dir.path().join(format!("session.{extension}"));
        let file_arg = file.display().to_string();
        let (mut serve, port, _stderr) =
            super::service::serve_with(&["--no-osc", "--duration", "3", "--record", &file_arg]);
        let reply = post_command(port, r#"{"type":"touch","id":1,"channel":1,"material":"aluminium"}"#);
        assert!(reply.contains(r#""request":"touch""#), "{reply}");
        let status = serve.0.wait().unwrap_or_else(|e| panic!("wait for serve: {e}"));
        assert!(status.success(), "serve --record {file_arg}: {status}");
        let csv = std::fs::read_dir(dir.path())
            .expect("the folder")
            .filter_map(Result::ok)
            .map(|e| e.path())
            .find(|p| p.extension().is_some_and(|e| e == "csv") && !p.to_string_lossy().ends_with(".events.csv"))
            .unwrap_or_else(|| panic!("no session CSV beside {file_arg}"));
        let table = thermode_table::read(&file).unwrap_or_else(|e| panic!("{file_arg}: {e}"));
        assert_same_as_csv(&table, &csv, &format!("serve --record .{extension}"));
        let touched =
            (0..table.rows()).filter(|&r| table.column("material").is_some_and(|m| m.field(r) == "aluminium"));
        let conductivity = table.column("conductivity_w_mk").expect("the property columns");
        let with_properties = touched.filter(|&r| !conductivity.field(r).is_empty()).count();
        assert!(
            with_properties > 10,
            "the touch's rows hold aluminium's properties ({with_properties} rows)"
        );
    }
}

/// The `_stim`/`_physio` signals of participant P01 in the BIDS folder `bids`: (file suffix, content) of each
/// gunzipped TSV and of each sidecar's sampling rate, start time and columns.
#[cfg(unix)]
fn exported_signals(bids: &Path) -> Vec<(String, String)> {
    let subject = bids.join("sub-P01");
    let session = std::fs::read_dir(&subject)
        .unwrap_or_else(|e| panic!("{}: {e}", subject.display()))
        .filter_map(Result::ok)
        .next()
        .expect("a session folder");
    let beh = session.path().join("beh");
    let mut signals = Vec::new();
    for entry in std::fs::read_dir(&beh).expect("beh").filter_map(Result::ok) {
        let name = entry.file_name().to_string_lossy().into_owned();
        let Some(suffix) = ["_stim.tsv.gz", "_physio.tsv.gz", "_stim.json", "_physio.json"]
            .into_iter()
            .find(|s| name.contains("_recording-") && name.ends_with(s))
        else {
            continue;
        };
        let content = if suffix.ends_with(".gz") {
            let mut text = String::new();
            std::io::Read::read_to_string(
                &mut flate2::read::GzDecoder::new(std::fs::File::open(entry.path()).expect("open")),
                &mut text,
            )
            .expect("gzip");
            text
        } else {
            let sidecar: serde_json::Value =
                serde_json::from_str(&std::fs::read_to_string(entry.path()).expect("read")).expect("json");
            format!(
                "{} {} {}",
                sidecar["SamplingFrequency"], sidecar["StartTime"], sidecar["Columns"]
            )
        };
        signals.push((suffix.to_string(), content));
    }
    signals.sort();
    signals
}

#[cfg(unix)]
#[test]
fn lab_export_reads_a_recording_from_arrow_or_parquet_as_from_its_csv() {
    let root = tempfile::tempdir().expect("temp dir");
    let path = |name: &str| root.path().join(name).display().to_string();
    let (data, arrow) = (path("data"), path("rec/session.arrow"));
    super::bids::observer_session(Path::new(&data), "P01");
    super::bids::short_recording(Path::new(&arrow), Path::new(&path("state")));
    let csv = std::fs::read_dir(path("rec"))
        .expect("the recording's folder")
        .filter_map(Result::ok)
        .map(|e| e.path())
        .find(|p| p.extension().is_some_and(|e| e == "csv") && !p.to_string_lossy().ends_with(".events.csv"))
        .expect("the session's CSV");
    let parquet = path("rec/session.parquet");
    let table = thermode_table::read(Path::new(&arrow)).unwrap_or_else(|e| panic!("{arrow}: {e}"));
    let mut bytes = Vec::new();
    thermode_table::write(&[table], thermode_table::Format::Parquet, &mut bytes).expect("parquet");
    std::fs::write(&parquet, bytes).expect("save the parquet file");
    assert!(
        Path::new(&path("rec/session.clock.json")).is_file(),
        "the clock sidecar copied beside the Arrow file"
    );
    let export = |recording: &str, folder: &str| {
        let given = format!("P01={recording}");
        expect_success(&[
            "lab",
            "export",
            "--bids",
            &path(folder),
            "--data-dir",
            &data,
            "--recording",
            &given,
        ]);
        exported_signals(Path::new(&path(folder)))
    };
    let from_csv = export(csv.to_str().expect("utf-8"), "bids-csv");
    assert_eq!(
        from_csv.len(),
        4,
        "stim and physio signals with their sidecars: {from_csv:?}"
    );
    let stim = from_csv
        .iter()
        .find(|(suffix, _)| suffix == "_stim.tsv.gz")
        .expect("a stim signal");
    assert!(
        stim.1.lines().count() > 20,
        "the signals hold the recording's ticks: {stim:?}"
    );
    for (file, folder) in [(&arrow, "bids-arrow"), (&parquet, "bids-parquet")] {
        let from_file = export(file, folder);
        assert_eq!(
            from_file, from_csv,
            "lab export --recording {file}: the signals and sidecars of the CSV"
        );
    }
}
