//! Every shaders/*.wgsl parses and validates with naga (all validation flags), every kernel is
//! listed in `acetab::engine::gpu::SHADERS`, and every host struct shared with WGSL has the size and
//! member offsets naga computes for the WGSL struct of the same role.

use acetab::engine::cpu::srvf_band::{BandHeader, BandRow};
use acetab::engine::gpu::{deform, project, silhouette, srvf_band, srvf_dp, surface, SHADERS};
use naga::valid::{Capabilities, ValidationFlags, Validator};
use std::mem::{offset_of, size_of};

fn parse(src: &str, name: &str) -> naga::Module {
    naga::front::wgsl::parse_str(src)
        .unwrap_or_else(|e| panic!("{name}: {}", e.emit_to_string(src)))
}

fn validate(src: &str, name: &str) -> Result<naga::valid::ModuleInfo, String> {
    let module = naga::front::wgsl::parse_str(src).map_err(|e| e.emit_to_string(src))?;
    Validator::new(ValidationFlags::all(), Capabilities::empty())
        .validate(&module)
        .map_err(|e| format!("{name}: {e:?}"))
}

#[test]
fn every_shader_file_validates_and_is_compiled_by_the_engine() {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("shaders");
    let mut files: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .filter_map(|e| e.ok())
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|x| x == "wgsl"))
        .map(|p| p.file_stem().unwrap().to_string_lossy().into_owned())
        .collect();
    files.sort();
    let mut listed: Vec<String> = SHADERS.iter().map(|(n, _)| n.to_string()).collect();
    listed.sort();
    assert_eq!(files, listed, "shaders/ and gpu::SHADERS differ");
    for (name, src) in SHADERS {
        let on_disk = std::fs::read_to_string(dir.join(format!("{name}.wgsl"))).unwrap();
        assert_eq!(on_disk, src);
        validate(src, name).unwrap();
    }
}

#[test]
fn validation_rejects_a_broken_shader() {
    // The companion: the same check must fail on a kernel with a type error.
    let broken = SHADERS[0]
        .1
        .replace("let p = rest[v].xyz;", "let p: u32 = rest[v].xyz;");
    assert_ne!(broken, SHADERS[0].1, "the replacement must hit");
    assert!(validate(&broken, "broken").is_err());
}

/// (size, member offsets) of the WGSL struct `name` in `src`.
fn wgsl_layout(src: &str, shader: &str, name: &str) -> (u32, Vec<u32>) {
    let module = parse(src, shader);
    let (_, ty) = module
        .types
        .iter()
        .find(|(_, t)| t.name.as_deref() == Some(name))
        .unwrap_or_else(|| panic!("{shader}: no struct {name}"));
    match &ty.inner {
        naga::TypeInner::Struct { members, span } => {
            (*span, members.iter().map(|m| m.offset).collect())
        }
        other => panic!("{shader}: {name} is {other:?}"),
    }
}

fn src(name: &str) -> &'static str {
    SHADERS.iter().find(|(n, _)| *n == name).unwrap().1
}

#[test]
fn host_structs_match_their_wgsl_layouts() {
    let cases: Vec<(&str, &str, usize, Vec<usize>)> = vec![
        (
            "deform",
            "Params",
            size_of::<deform::DeformParams>(),
            vec![
                offset_of!(deform::DeformParams, vertex_count),
                offset_of!(deform::DeformParams, node_count),
                offset_of!(deform::DeformParams, neighbours),
                offset_of!(deform::DeformParams, mesh_count),
            ],
        ),
        (
            "project",
            "Params",
            size_of::<project::ProjectParams>(),
            vec![
                offset_of!(project::ProjectParams, vertex_count),
                offset_of!(project::ProjectParams, mesh_count),
                offset_of!(project::ProjectParams, view_count),
                offset_of!(project::ProjectParams, _pad),
            ],
        ),
        (
            "project",
            "View",
            size_of::<project::GpuView>(),
            vec![
                offset_of!(project::GpuView, r0),
                offset_of!(project::GpuView, r1),
                offset_of!(project::GpuView, r2),
                offset_of!(project::GpuView, k),
            ],
        ),
        (
            "silhouette",
            "Window",
            size_of::<silhouette::SilhouetteWindow>(),
            vec![
                offset_of!(silhouette::SilhouetteWindow, x0),
                offset_of!(silhouette::SilhouetteWindow, y0),
                offset_of!(silhouette::SilhouetteWindow, scale),
                offset_of!(silhouette::SilhouetteWindow, size),
            ],
        ),
        (
            "surface",
            "View",
            size_of::<surface::SurfaceView>(),
            vec![
                offset_of!(surface::SurfaceView, u),
                offset_of!(surface::SurfaceView, v),
                offset_of!(surface::SurfaceView, w),
                offset_of!(surface::SurfaceView, c),
            ],
        ),
        (
            "srvf_dp",
            "Params",
            size_of::<srvf_dp::DpParams>(),
            vec![
                offset_of!(srvf_dp::DpParams, samples),
                offset_of!(srvf_dp::DpParams, problems),
                offset_of!(srvf_dp::DpParams, step_count),
                offset_of!(srvf_dp::DpParams, _pad),
            ],
        ),
        (
            "srvf_dp",
            "Step",
            size_of::<srvf_dp::GpuStep>(),
            vec![
                offset_of!(srvf_dp::GpuStep, a),
                offset_of!(srvf_dp::GpuStep, b),
                offset_of!(srvf_dp::GpuStep, sqrt_slope),
                offset_of!(srvf_dp::GpuStep, tap_start),
            ],
        ),
        (
            "srvf_dp",
            "Tap",
            size_of::<srvf_dp::GpuTap>(),
            vec![
                offset_of!(srvf_dp::GpuTap, offset),
                offset_of!(srvf_dp::GpuTap, frac),
            ],
        ),
        (
            "srvf_band",
            "Params",
            size_of::<srvf_band::BandParams>(),
            vec![
                offset_of!(srvf_band::BandParams, problems),
                offset_of!(srvf_band::BandParams, step_count),
                offset_of!(srvf_band::BandParams, _pad),
                offset_of!(srvf_band::BandParams, _pad) + 4,
            ],
        ),
        (
            "srvf_band",
            "Problem",
            size_of::<BandHeader>(),
            vec![
                offset_of!(BandHeader, n),
                offset_of!(BandHeader, rows),
                offset_of!(BandHeader, cells),
                offset_of!(BandHeader, curve),
                offset_of!(BandHeader, weight),
                offset_of!(BandHeader, _pad),
                offset_of!(BandHeader, _pad) + 4,
                offset_of!(BandHeader, _pad) + 8,
            ],
        ),
        (
            "srvf_band",
            "Row",
            size_of::<BandRow>(),
            vec![
                offset_of!(BandRow, lo),
                offset_of!(BandRow, hi),
                offset_of!(BandRow, offset),
                offset_of!(BandRow, _pad),
            ],
        ),
        (
            "srvf_band",
            "Step",
            size_of::<srvf_dp::GpuStep>(),
            vec![
                offset_of!(srvf_dp::GpuStep, a),
                offset_of!(srvf_dp::GpuStep, b),
                offset_of!(srvf_dp::GpuStep, sqrt_slope),
                offset_of!(srvf_dp::GpuStep, tap_start),
            ],
        ),
        (
            "srvf_band",
            "Tap",
            size_of::<srvf_dp::GpuTap>(),
            vec![
                offset_of!(srvf_dp::GpuTap, offset),
                offset_of!(srvf_dp::GpuTap, frac),
            ],
        ),
    ];
    for (shader, name, size, offsets) in cases {
        let (wsize, woffsets) = wgsl_layout(src(shader), shader, name);
        assert_eq!(wsize as usize, size, "{shader}::{name} size");
        let woffsets: Vec<usize> = woffsets.into_iter().map(|o| o as usize).collect();
        assert_eq!(woffsets, offsets, "{shader}::{name} offsets");
    }
}

#[test]
fn layout_check_rejects_a_drifted_struct() {
    // The companion: a WGSL struct with an extra member no longer matches the host's size.
    let drifted = src("srvf_dp").replace(
        "    tap_start: u32,  // first",
        "    tap_start: u32,\n    extra: vec2<f32>,  // first",
    );
    assert_ne!(drifted, src("srvf_dp"));
    let (size, _) = wgsl_layout(&drifted, "drifted", "Step");
    assert_ne!(size as usize, size_of::<srvf_dp::GpuStep>());
}
