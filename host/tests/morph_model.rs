//! `morph-model` as a user runs it: the repository's `link.toml` by default from any directory
//! of the checkout, a new geometry flagged, data from another geometry refused, a bad value named.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .parent()
        .unwrap()
        .to_path_buf()
}

fn morph_model(dir: &Path, args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_morph-model"))
        .current_dir(dir)
        .args(args)
        .output()
        .expect("run morph-model")
}

fn text(b: &[u8]) -> String {
    String::from_utf8_lossy(b).into_owned()
}

/// A scratch directory of this test process.
fn scratch(name: &str) -> PathBuf {
    let d = std::env::temp_dir().join(format!("morph-model-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn repo_link_with(from: &str, to: &str, name: &str) -> PathBuf {
    let base = std::fs::read_to_string(root().join("link.toml")).unwrap();
    assert!(base.contains(from));
    let path = scratch(name).join("link.toml");
    std::fs::write(&path, base.replacen(from, to, 1)).unwrap();
    path
}

#[test]
fn reads_the_repository_link_toml_from_a_subdirectory() {
    let link = root().join("link.toml");
    let by_default = morph_model(&root().join("model/src"), &["table"]);
    let named = morph_model(&root(), &["--link", link.to_str().unwrap(), "table"]);
    assert!(by_default.status.success(), "{}", text(&by_default.stderr));
    assert_eq!(text(&by_default.stdout), text(&named.stdout));
    // The repository's link is the fitted one: no note.
    assert_eq!(text(&by_default.stderr), "");
    // And it really is that file: an edited table size shows in a table read with --link.
    let edited = repo_link_with("table_entries = 16", "table_entries = 4", "entries");
    let out = morph_model(&root(), &["--link", edited.to_str().unwrap(), "table"]);
    assert_eq!(text(&out.stdout).lines().count(), 5);
}

#[test]
fn a_new_geometry_is_flagged_and_the_old_data_refused() {
    let wide = repo_link_with("body_diameter_m = 0.008", "body_diameter_m = 0.010", "wide");
    let out = morph_model(&root(), &["--link", wide.to_str().unwrap(), "table"]);
    assert!(out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("new geometry, no measured radii")
            && err.contains("geometry.body_diameter_m = 0.01 (fitted on 0.008)"),
        "{err}"
    );
    let out = morph_model(&root(), &["--link", wide.to_str().unwrap(), "calibrate"]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains("measured on another geometry") && err.contains("fig9_calibration.csv"),
        "{err}"
    );
}

#[test]
fn calibrate_fits_data_measured_on_the_geometry_and_writes_where_it_came_from() {
    let wide = repo_link_with("body_diameter_m = 0.008", "body_diameter_m = 0.010", "fit");
    let dir = wide.parent().unwrap().to_path_buf();
    let data = dir.join("radii.csv");
    // Without a geometry line or --measured-on: refused, and told what line to add.
    std::fs::write(
        &data,
        "p_tca_w,radius_mm,source\n0.1,80.0,measured\n0.8,66.0,measured\n1.5,58.5,measured\n",
    )
    .unwrap();
    let args = |extra: &[&str]| {
        let mut a = vec!["--link", wide.to_str().unwrap(), "calibrate", "--data"];
        a.push(data.to_str().unwrap());
        a.extend_from_slice(extra);
        a.iter().map(|s| s.to_string()).collect::<Vec<_>>()
    };
    let run = |a: Vec<String>| {
        let a: Vec<&str> = a.iter().map(String::as_str).collect();
        morph_model(&root(), &a)
    };
    let out = run(args(&[]));
    assert!(!out.status.success());
    assert!(
        text(&out.stderr).contains("# geometry: body_diameter_m = 0.01"),
        "{}",
        text(&out.stderr)
    );
    // Measured on this link: fitted, and the written file records the geometry.
    let fitted = dir.join("fitted.toml");
    let out = run(args(&[
        "--measured-on",
        wide.to_str().unwrap(),
        "--write",
        fitted.to_str().unwrap(),
    ]));
    assert!(out.status.success(), "{}", text(&out.stderr));
    let out = morph_model(&root(), &["--link", fitted.to_str().unwrap(), "table"]);
    assert!(out.status.success(), "{}", text(&out.stderr));
    assert_eq!(text(&out.stderr), "", "a refitted geometry is not flagged");
    let at_0p8: f64 = text(&out.stdout)
        .lines()
        .find(|l| l.starts_with("0.8000,"))
        .and_then(|l| l.split(',').nth(1))
        .unwrap()
        .parse()
        .unwrap();
    assert!(
        (at_0p8 - 66.0).abs() < 1.5,
        "fitted radius at 0.8 W {at_0p8}"
    );
}

#[test]
fn a_bad_value_names_the_file_the_key_and_the_range() {
    let bad = repo_link_with("ambient_c = 22.0", "ambient_c = 400.0", "bad");
    let out = morph_model(&root(), &["--link", bad.to_str().unwrap(), "table"]);
    assert!(!out.status.success());
    let err = text(&out.stderr);
    assert!(
        err.contains(bad.to_str().unwrap())
            && err.contains("surroundings.ambient_c = 400")
            && err.contains("-20..=45 °C"),
        "{err}"
    );
    assert_eq!(text(&out.stdout), "", "nothing printed for a bad file");
}

#[test]
fn outside_the_checkout_it_says_what_it_needs_and_how_to_run_it() {
    let dir = scratch("outside");
    let out = morph_model(&dir, &["params"]);
    let err = text(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(!err.contains("cargo metadata"), "{err}");
    assert!(
        err.contains("is not inside the morphlink checkout"),
        "{err}"
    );
    assert!(err.contains("pass --link FILE"), "{err}");
    // A cargo project that is not morphlink.
    std::fs::write(
        dir.join("Cargo.toml"),
        "[package]\nname = \"other\"\nversion = \"0.1.0\"\nedition = \"2021\"\n",
    )
    .unwrap();
    std::fs::create_dir_all(dir.join("src")).unwrap();
    std::fs::write(dir.join("src/lib.rs"), "").unwrap();
    let out = morph_model(&dir, &["params"]);
    let err = text(&out.stderr);
    assert!(!out.status.success(), "{err}");
    assert!(err.contains("without link.toml"), "{err}");
    let _ = std::fs::remove_dir_all(&dir);
}
