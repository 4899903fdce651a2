//! The study runner: results do not depend on the thread count, shards merge to the unsharded
//! table, and the output folder holds what the README promises.

use acetab::engine::Kernels;
use acetab::pipeline::ReconParams;
use acetab::sim::{phantom, PhantomParams};
use acetab::study::StudyMethod;
use acetab::study::{
    merge_dirs, run_study, write_csv, write_examples, write_tables, Row, StudyConfig,
};

fn quick() -> StudyConfig {
    let mut params = ReconParams::default();
    params.placement.rounds = 4;
    params.deformation.correspondence_updates = 1;
    params.correspond.srvf.samples = 64;
    params.deformation.graph.nodes = 40;
    StudyConfig {
        levels: vec![1, 4],
        runs: 2,
        methods: vec![StudyMethod::Srvf, StudyMethod::Icp],
        seed: 11,
        threads: 1,
        template: acetab::template::TemplateParams {
            vertices: 700,
            ..Default::default()
        },
        params,
        ..Default::default()
    }
}

fn small_phantom() -> acetab::geom::Mesh {
    phantom(&PhantomParams {
        vertices: 1200,
        ..Default::default()
    })
    .mesh
}

/// Everything but the wall-clock time, as text (so NaN of failed runs compares equal).
fn strip(rows: &[Row]) -> String {
    format!(
        "{:?}",
        rows.iter()
            .map(|r| Row {
                seconds: 0.0,
                ..r.clone()
            })
            .collect::<Vec<_>>()
    )
}

#[test]
fn threads_and_shards_give_the_same_table() {
    let truth = small_phantom();
    let cfg = quick();
    let (one, examples) = run_study(&truth, &cfg, &|| {}, Kernels::Cpu).unwrap();
    assert_eq!(one.len(), 8);
    let (two, _) = run_study(
        &truth,
        &StudyConfig {
            threads: 2,
            ..cfg.clone()
        },
        &|| {},
        Kernels::Cpu,
    )
    .unwrap();
    assert_eq!(strip(&one), strip(&two));
    let tmp = tempfile::tempdir().unwrap();
    let base = tmp.path();
    let mut dirs = Vec::new();
    for i in 0..3 {
        let (rows, _) = run_study(
            &truth,
            &StudyConfig {
                shard: (i, 3),
                threads: 2,
                ..cfg.clone()
            },
            &|| {},
            Kernels::Cpu,
        )
        .unwrap();
        let d = base.join(format!("shard{i}"));
        std::fs::create_dir_all(&d).unwrap();
        write_csv(&rows, &d.join("runs.csv")).unwrap();
        dirs.push(d);
    }
    let merged = merge_dirs(&dirs).unwrap();
    // The CSV keeps 6 decimals: compare the unsharded table through the same file.
    let d = base.join("all");
    std::fs::create_dir_all(&d).unwrap();
    write_csv(&one, &d.join("runs.csv")).unwrap();
    let one_csv = merge_dirs(std::slice::from_ref(&d)).unwrap();
    assert_eq!(strip(&merged), strip(&one_csv));
    // A perturbed shard is told apart (the comparison can fail).
    let mut wrong = merged.clone();
    wrong[3].mae_mm += 1e-3;
    assert_ne!(strip(&wrong), strip(&one_csv));

    write_tables(&one, &d, &serde_json::json!({"seed": 11})).unwrap();
    write_examples(&examples, &truth, &d).unwrap();
    for f in [
        "runs.csv",
        "summary.json",
        "errors.png",
        "example-srvf/reconstruction.ply",
        "example-srvf/view0.png",
        "example-icp/view2.png",
    ] {
        assert!(d.join(f).is_file(), "{f}");
    }
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["summary"].as_array().unwrap().len(), 4);
}

#[test]
fn paper_protocol_runs_only_the_deformation_and_keeps_its_name() {
    let truth = small_phantom();
    let cfg = StudyConfig {
        levels: vec![1],
        runs: 1,
        methods: vec![StudyMethod::Icp, StudyMethod::IcpPaper],
        ..quick()
    };
    let (rows, examples) = run_study(&truth, &cfg, &|| {}, Kernels::Cpu).unwrap();
    let [ours, paper] = [&rows[0], &rows[1]];
    assert_eq!(
        (ours.method, paper.method),
        (StudyMethod::Icp, StudyMethod::IcpPaper)
    );
    assert!(ours.error.is_empty() && paper.error.is_empty());
    // Ours placed the template on the limb sphere and ran the similarity stage (several
    // solver iterations per round) before the deformation's one iteration per round.
    assert!(ours.limb_diameter_mm.is_finite());
    assert!(ours.iterations > cfg.params.deformation.icp_iterations);
    // The paper's protocol: no limb sphere, no similarity stage.
    assert!(
        paper.limb_diameter_mm.is_nan(),
        "{}",
        paper.limb_diameter_mm
    );
    assert!(paper.iterations <= cfg.params.deformation.icp_iterations);
    let ex = examples
        .iter()
        .find(|e| e.task.method == StudyMethod::IcpPaper)
        .unwrap();
    assert_eq!(ex.recon.log.similarity_rounds, 0);
    assert!(ex.recon.log.limb_sphere.is_none());

    let tmp = tempfile::tempdir().unwrap();
    let d = tmp.path().to_path_buf();
    write_tables(&rows, &d, &serde_json::json!({})).unwrap();
    write_examples(&examples, &truth, &d).unwrap();
    let back = merge_dirs(std::slice::from_ref(&d)).unwrap();
    assert_eq!(back[1].method, StudyMethod::IcpPaper);
    assert!(d.join("example-icp-paper/view1.png").is_file());
    let summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(d.join("summary.json")).unwrap()).unwrap();
    assert_eq!(summary["summary"][1]["method"], "icp-paper");
}
