//! What a study checks before it trains and what its tables say, run as a user runs them:
//! benchmark samples whose views differ in size or whose ground truth is cut short fail
//! `experiment check` and `ablate` before any training, naming the files (and fail, without a
//! panic, when evaluated outside them); two runs of one name fail before anything is written; a
//! refused `ablate` writes nothing; `--collect` takes each row's steps from its runs' records and
//! marks runs whose file changed since as stale; `--wait` needs Slurm; `--paper` matches the
//! paper's columns by data set, not by name, and says so; `ablation.md` says what each row is and
//! how each benchmark is scored.

mod common;

use std::path::{Path, PathBuf};

use common::{SYNTHETIC_SOURCE, TINY_VALIDATION, cones_dir, dgstereo, text, tiny_train, write_experiment};

/// A `[[benchmarks]]` entry scoring the folder `root` as `name`, 2 iterations, at most 96 px.
fn folder_benchmark(name: &str, root: &Path) -> String {
    format!(
        "[[benchmarks]]\nname = \"{name}\"\ndataset = \"folder\"\nroot = '{}'\niters = 2\nmax_size = 96\n",
        root.display()
    )
}

/// A three-step tiny run `name` in `dir/<file>`, scored on `benchmarks`; `train_extra` lines go
/// into `[train]`, `extra` after everything.
fn study_file(dir: &Path, file: &str, name: &str, train_extra: &str, extra: &str) -> PathBuf {
    let train = tiny_train(3, 1, 7, 2, train_extra);
    write_experiment(dir, file, name, &train, &format!("{SYNTHETIC_SOURCE}{TINY_VALIDATION}"), extra)
}

/// A copy of the bundled Cones folder.
fn cones_copy(to: &Path) -> PathBuf {
    std::fs::create_dir_all(to).unwrap();
    for entry in std::fs::read_dir(cones_dir()).unwrap() {
        let path = entry.unwrap().path();
        if path.is_file() {
            std::fs::copy(&path, to.join(path.file_name().unwrap())).unwrap();
        }
    }
    to.to_path_buf()
}

#[test]
fn broken_benchmark_samples_fail_before_training_and_never_panic() {
    let dir = tempfile::tempdir().unwrap();
    // Views of different sizes: the right view one column narrower.
    let views = cones_copy(&dir.path().join("views"));
    let right = dgstereo_data::load_rgb(views.join("right_rgb.png")).unwrap();
    let narrower = right.crop(0, 0, right.width - 1, right.height).unwrap();
    dgstereo_data::save_rgb(views.join("right_rgb.png"), &narrower).unwrap();
    // A ground truth cut short, as by an interrupted copy.
    let cut = cones_copy(&dir.path().join("cut"));
    let gt = std::fs::read(cut.join("disp_left.pfm")).unwrap();
    std::fs::write(cut.join("disp_left.pfm"), &gt[..gt.len() / 2]).unwrap();

    let cases = [(&views, "right_rgb.png", "left_rgb.png"), (&cut, "disp_left.pfm", "truncated")];
    for (i, (folder, file, also)) in cases.into_iter().enumerate() {
        let name = format!("broken{i}");
        let exp = study_file(dir.path(), &format!("{name}.toml"), &name, "", &folder_benchmark("cones", folder));
        let bad_file = folder.join(file).display().to_string();
        let o = dgstereo(&["experiment", "check", exp.to_str().unwrap()]);
        let said = text(&o);
        assert!(!o.status.success(), "{said}");
        assert!(said.contains(&bad_file) && said.contains(also) && said.contains("benchmarks[0]"), "{said}");
        assert!(!said.contains("panicked"), "{said}");

        let out = dir.path().join(format!("study{i}"));
        let o = dgstereo(&["ablate", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"]);
        let said = text(&o);
        assert!(!o.status.success(), "{said}");
        assert!(said.contains(&bad_file) && said.contains(also), "{said}");
        assert!(!said.contains("panicked"), "{said}");
        assert!(!out.exists(), "ablate wrote {} before its check failed", out.display());
    }

    // The same sample evaluated outside a study's check: an error naming the files, no panic.
    let out = dir.path().join("eval");
    let o = dgstereo(&[
        "eval",
        "--dataset",
        "folder",
        "--root",
        views.to_str().unwrap(),
        "--iters",
        "1",
        "--out",
        out.to_str().unwrap(),
    ]);
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(said.contains("right_rgb.png") && said.contains("left_rgb.png"), "{said}");
    assert!(!said.contains("panicked"), "{said}");
}

#[test]
fn two_runs_of_one_name_fail_before_anything_is_written() {
    let dir = tempfile::tempdir().unwrap();
    let a = study_file(dir.path(), "a.toml", "same", "", &folder_benchmark("cones", &cones_dir()));
    let b = study_file(dir.path(), "b.toml", "same", "", &folder_benchmark("cones", &cones_dir()));
    let o = dgstereo(&["experiment", "check", a.to_str().unwrap(), b.to_str().unwrap()]);
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(
        said.contains("run name 'same' is given twice") && said.contains("a.toml") && said.contains("b.toml"),
        "{said}"
    );
    let out = dir.path().join("study");
    let o = dgstereo(&["ablate", a.to_str().unwrap(), b.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(!o.status.success() && text(&o).contains("given twice"), "{}", text(&o));
    assert!(!out.exists(), "nothing is written");
    // --wait belongs to Slurm: refused with the local launcher, before anything runs.
    let o = dgstereo(&["ablate", a.to_str().unwrap(), "--out", out.to_str().unwrap(), "--wait"]);
    let said = text(&o);
    assert!(!o.status.success() && said.contains("--wait") && said.contains("--launcher slurm"), "{said}");
    assert!(!out.exists(), "nothing is written");
}

#[test]
fn a_refused_ablate_writes_nothing_and_collect_reads_each_runs_record() {
    let dir = tempfile::tempdir().unwrap();
    let exp = study_file(dir.path(), "rec.toml", "rec", "", &folder_benchmark("cones", &cones_dir()));
    let out = dir.path().join("study");
    let o = dgstereo(&["ablate", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet", "--paper"]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    // The run is a RAFT-Stereo network: --paper lays it out as the paper's Table 1 beside
    // RAFT-Stereo's published figures; its folder benchmark is none of the table's data sets.
    assert!(
        said.contains("### Table 1: zero-shot generalisation") && said.contains("| RAFT-Stereo | `rec` |"),
        "{said}"
    );
    let table1 = std::fs::read_to_string(out.join("paper-table1.csv")).unwrap();
    assert!(table1.contains("\nRAFT-Stereo,rec,paper,1.43,11.21,1.89,9.87,"), "{table1}");
    assert!(table1.contains(&format!("\nRAFT-Stereo,rec,ours{}\n", ",".repeat(14))), "{table1}");
    let (study, csv) = (out.join("study.json"), out.join("ablation.csv"));
    let (study_before, csv_before) = (std::fs::read(&study).unwrap(), std::fs::read_to_string(&csv).unwrap());
    assert!(csv_before.lines().nth(1).unwrap().starts_with("rec,1,3,"), "{csv_before}");

    // Another step count is another training: refused, and nothing changes, study.json included.
    let o = dgstereo(&["ablate", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet", "--steps", "2"]);
    let said = text(&o);
    assert!(!o.status.success(), "{said}");
    assert!(said.contains("nothing was changed") && said.contains("train.steps: 2 here, 3 in the run"), "{said}");
    assert_eq!(std::fs::read(&study).unwrap(), study_before, "a refused ablate rewrote study.json");
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), csv_before);

    // A study record that claims other steps than the run trained (as one rewritten by a refused
    // command once did): the run is stale, never a row labelled with the claimed steps.
    let claimed = String::from_utf8(study_before.clone()).unwrap().replace("\"steps\": null", "\"steps\": 2");
    std::fs::write(&study, claimed).unwrap();
    let o = dgstereo(&["ablate", "--collect", "--out", out.to_str().unwrap()]);
    let md = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    assert!(!o.status.success(), "{}", text(&o));
    assert!(md.contains("| rec | 0 | – | stale:") && md.contains("train.steps: 2 here, 3 in the run"), "{md}");
    std::fs::write(&study, &study_before).unwrap();
    let o = dgstereo(&["ablate", "--collect", "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", text(&o));
    assert_eq!(std::fs::read_to_string(&csv).unwrap(), csv_before, "the run's own record: 3 steps");

    // The file changed since the run trained: its row is marked stale, the study fails.
    study_file(dir.path(), "rec.toml", "rec", "lr = 0.001\n", &folder_benchmark("cones", &cones_dir()));
    let o = dgstereo(&["ablate", "--collect", "--out", out.to_str().unwrap()]);
    let md = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    assert!(!o.status.success(), "{}", text(&o));
    assert!(md.contains("| rec | 0 | – | stale:") && md.contains("train.lr: 0.001 here, 0.0002 in the run"), "{md}");
}

#[test]
fn paper_columns_match_by_data_set_and_the_table_says_what_it_measured() {
    let dir = tempfile::tempdir().unwrap();
    // A row of the paper's (by run name), scored on a folder that is named like a DrivingStereo
    // weather but is not one.
    let exp = study_file(dir.path(), "dgia.toml", "+dgia", "", &folder_benchmark("drivingstereo-sunny", &cones_dir()));
    let body = std::fs::read_to_string(&exp).unwrap();
    std::fs::write(&exp, format!("description = \"a tiny stand-in for +DGIA\"\n{body}")).unwrap();
    let out = dir.path().join("study");
    let o = dgstereo(&["ablate", exp.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet", "--paper"]);
    let said = text(&o);
    assert!(o.status.success(), "{said}");
    assert!(said.contains("the paper's columns, matched by data set"), "{said}");
    assert!(
        said.contains("DS-Sunny: no benchmark of the study (dataset = \"drivingstereo\", weather = \"sunny\")"),
        "{said}"
    );
    let table2 = std::fs::read_to_string(out.join("paper-table2.csv")).unwrap();
    let ours = table2.lines().find(|l| l.starts_with("+DGIA,+dgia,ours")).expect("the row is the paper's");
    assert_eq!(ours, "+DGIA,+dgia,ours,,,,,,,,", "a folder is not DrivingStereo, whatever its name");
    let paper = std::fs::read_to_string(out.join("paper-tables.md")).unwrap();
    assert!(paper.contains("Columns matched") && paper.contains("- ETH3D: no benchmark of the study"), "{paper}");

    let md = std::fs::read_to_string(out.join("ablation.md")).unwrap();
    assert!(md.contains("- `+dgia` (seed 7, 3 steps): a tiny stand-in for +DGIA"), "{md}");
    let cones = std::fs::canonicalize(cones_dir()).unwrap();
    let settings =
        format!("- drivingstereo-sunny: folder at {}, 2 iterations, longer side at most 96 px", cones.display());
    assert!(md.contains(&settings), "{md}");
    assert!(md.contains("- synthetic: held-out synthetic pairs of 64x32"), "{md}");
}
