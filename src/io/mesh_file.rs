//! Mesh files: STL (ASCII and binary, via `stl_io`), PLY (ASCII, with per-vertex colour, via
//! `ply-rs`) and OBJ (read via `tobj`; written by hand, the format is three line kinds).

use crate::geom::{Mesh, MeshError};
use crate::io::write_atomic;
use nalgebra::Point3;
use std::path::{Path, PathBuf};

/// A mesh file could not be read or written.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum MeshIoError {
    /// The file cannot be read or written.
    #[error("{path}: cannot read: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The file is not valid in its format.
    #[error("{path}: not a valid {format} file: {reason}")]
    Parse {
        /// The file.
        path: PathBuf,
        /// STL, PLY or OBJ.
        format: &'static str,
        /// What is wrong.
        reason: String,
    },
    /// An extension that is not .stl, .ply or .obj.
    #[error("{path}: unsupported mesh extension {ext:?} (use .stl, .ply or .obj)")]
    Extension {
        /// The file.
        path: PathBuf,
        /// Its extension.
        ext: String,
    },
    /// The file's mesh is unusable.
    #[error("{path}: {source}")]
    Mesh {
        /// The file.
        path: PathBuf,
        /// Why its mesh is unusable.
        source: MeshError,
    },
}

/// An RGB colour per vertex, for error maps.
pub type Rgb = [u8; 3];

fn ext_of(path: &Path) -> String {
    path.extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase())
        .unwrap_or_default()
}

/// Read an STL, PLY or OBJ file (by extension). STL corners are welded at 1e-6 mm.
pub fn read_mesh(path: &Path) -> Result<Mesh, MeshIoError> {
    let io = |source| MeshIoError::Io {
        path: path.to_path_buf(),
        source,
    };
    let (vertices, triangles) = match ext_of(path).as_str() {
        "stl" => read_stl(path)?,
        "ply" => read_ply(path)?,
        "obj" => read_obj(path)?,
        // A path that is not there is named as missing, whatever its extension says (a
        // folder or file name mistyped reads better so than as an unsupported extension).
        _ if !path.exists() => {
            return Err(io(std::io::Error::new(
                std::io::ErrorKind::NotFound,
                "no such file or folder",
            )))
        }
        _ if path.is_dir() => {
            return Err(io(std::io::Error::other(
                "a folder, not a mesh file (.stl, .ply or .obj)",
            )))
        }
        ext => {
            return Err(MeshIoError::Extension {
                path: path.to_path_buf(),
                ext: ext.to_string(),
            })
        }
    };
    let mesh = Mesh::new(vertices, triangles).map_err(|source| MeshIoError::Mesh {
        path: path.to_path_buf(),
        source,
    })?;
    mesh.welded(1e-6).map_err(|source| MeshIoError::Mesh {
        path: path.to_path_buf(),
        source,
    })
}

/// An STL file's corners (not yet welded) and triangles: its size must agree with the triangle
/// count in its header (`stl_size_mismatch`).
fn read_stl(path: &Path) -> Result<RawMesh, MeshIoError> {
    let bytes = std::fs::read(path).map_err(|source| MeshIoError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let parse = |reason: String| MeshIoError::Parse {
        path: path.to_path_buf(),
        format: "STL",
        reason: super::printable(&reason),
    };
    let m = stl_io::read_stl(&mut std::io::Cursor::new(&bytes))
        .map_err(|e| parse(stl_size_mismatch(&bytes, None).unwrap_or_else(|| e.to_string())))?;
    if let Some(reason) = stl_size_mismatch(&bytes, Some(m.faces.len())) {
        return Err(parse(reason));
    }
    let v = m
        .vertices
        .iter()
        .map(|v| Point3::new(v[0] as f64, v[1] as f64, v[2] as f64))
        .collect();
    let t = m
        .faces
        .iter()
        .map(|f| f.vertices.map(|i| i as u32))
        .collect();
    Ok((v, t))
}

/// An OBJ file's vertices and triangles (faces triangulated, one index per corner), every model
/// in it one after the other.
fn read_obj(path: &Path) -> Result<RawMesh, MeshIoError> {
    let opts = tobj::LoadOptions {
        triangulate: true,
        single_index: true,
        ..Default::default()
    };
    let (models, _) = tobj::load_obj(path, &opts).map_err(|e| match e {
        tobj::LoadError::OpenFileFailed => MeshIoError::Io {
            path: path.to_path_buf(),
            source: std::io::Error::new(std::io::ErrorKind::NotFound, "open failed"),
        },
        e => MeshIoError::Parse {
            path: path.to_path_buf(),
            format: "OBJ",
            reason: super::printable(&e.to_string()),
        },
    })?;
    let mut v = Vec::new();
    let mut t = Vec::new();
    for m in models {
        let base = v.len() as u32;
        v.extend(
            m.mesh
                .positions
                .chunks_exact(3)
                .map(|p| Point3::new(p[0] as f64, p[1] as f64, p[2] as f64)),
        );
        t.extend(
            m.mesh
                .indices
                .chunks_exact(3)
                .map(|c| [c[0] + base, c[1] + base, c[2] + base]),
        );
    }
    Ok((v, t))
}

/// Where a binary STL's size disagrees with the triangle count in its header, what is wrong.
/// `read`: the triangles the file gave when it was read (None where it could not be read). A
/// header whose count is the triangles read, followed by at least one more triangle's bytes,
/// would silently drop them; a file shorter than its header says cannot be read at all. An
/// ASCII STL (starting with "solid") whose bytes 80-84 happen to be read as a count is left to
/// its reader: it is not binary unless what was read matches that count.
fn stl_size_mismatch(bytes: &[u8], read: Option<usize>) -> Option<String> {
    const HEADER: u64 = 84;
    const TRIANGLE: u64 = 50;
    let declared = u32::from_le_bytes(bytes.get(80..84)?.try_into().ok()?) as u64;
    let expected = HEADER + TRIANGLE * declared;
    let len = bytes.len() as u64;
    let mismatch = match read {
        Some(n) => n as u64 == declared && len >= expected + TRIANGLE,
        None => !bytes.starts_with(b"solid") && len != expected,
    };
    mismatch.then(|| {
        format!(
            "binary STL whose header says {declared} triangles ({expected} bytes), but the file \
             has {len} bytes{}: is the header's triangle count wrong, or the file cut or joined \
             to another?",
            if len > expected {
                let more = (len - expected) / TRIANGLE;
                let what = if more == 1 {
                    "triangle's"
                } else {
                    "triangles'"
                };
                format!(", {more} more {what} worth after them")
            } else {
                String::new()
            }
        )
    })
}

/// Vertices and triangles as read, before the mesh is checked and welded.
type RawMesh = (Vec<Point3<f64>>, Vec<[u32; 3]>);

fn read_ply(path: &Path) -> Result<RawMesh, MeshIoError> {
    use ply_rs::ply::Property;
    let parse = |reason: String| MeshIoError::Parse {
        path: path.to_path_buf(),
        format: "PLY",
        reason: super::printable(&reason),
    };
    let f = std::fs::File::open(path).map_err(|source| MeshIoError::Io {
        path: path.to_path_buf(),
        source,
    })?;
    let mut r = std::io::BufReader::new(f);
    let parser = ply_rs::parser::Parser::<ply_rs::ply::DefaultElement>::new();
    // ply-rs's messages run over several lines; an error is one line.
    let ply = parser.read_ply(&mut r).map_err(|e| {
        parse(
            e.to_string()
                .split_whitespace()
                .collect::<Vec<_>>()
                .join(" "),
        )
    })?;
    let scalar = |p: Option<&Property>, name: &str, i: usize| -> Result<f64, MeshIoError> {
        match p {
            Some(Property::Float(v)) => Ok(*v as f64),
            Some(Property::Double(v)) => Ok(*v),
            Some(Property::Int(v)) => Ok(*v as f64),
            Some(Property::Short(v)) => Ok(*v as f64),
            _ => Err(parse(format!(
                "vertex {i} has no numeric property {name:?}"
            ))),
        }
    };
    let verts = ply
        .payload
        .get("vertex")
        .ok_or_else(|| parse("no vertex element".into()))?;
    let mut v = Vec::with_capacity(verts.len());
    for (i, e) in verts.iter().enumerate() {
        v.push(Point3::new(
            scalar(e.get("x"), "x", i)?,
            scalar(e.get("y"), "y", i)?,
            scalar(e.get("z"), "z", i)?,
        ));
    }
    let faces = ply
        .payload
        .get("face")
        .ok_or_else(|| parse("no face element".into()))?;
    let mut t = Vec::with_capacity(faces.len());
    for (i, e) in faces.iter().enumerate() {
        let idx: Vec<i64> = match e.get("vertex_indices").or_else(|| e.get("vertex_index")) {
            Some(Property::ListInt(l)) => l.iter().map(|&x| x as i64).collect(),
            Some(Property::ListUInt(l)) => l.iter().map(|&x| x as i64).collect(),
            Some(Property::ListUChar(l)) => l.iter().map(|&x| x as i64).collect(),
            Some(Property::ListShort(l)) => l.iter().map(|&x| x as i64).collect(),
            Some(Property::ListUShort(l)) => l.iter().map(|&x| x as i64).collect(),
            _ => return Err(parse(format!("face {i} has no vertex_indices list"))),
        };
        if idx.len() < 3 || idx.iter().any(|&x| x < 0 || x > u32::MAX as i64) {
            return Err(parse(format!(
                "face {i} has invalid vertex_indices {idx:?}"
            )));
        }
        for k in 1..idx.len() - 1 {
            t.push([idx[0] as u32, idx[k] as u32, idx[k + 1] as u32]);
        }
    }
    Ok((v, t))
}

fn write_err(path: &Path) -> impl Fn(std::io::Error) -> MeshIoError + '_ {
    move |source| MeshIoError::Io {
        path: path.to_path_buf(),
        source,
    }
}

/// Write a binary STL.
pub fn write_stl_binary(mesh: &Mesh, path: &Path) -> Result<(), MeshIoError> {
    let tris: Vec<stl_io::Triangle> = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
            let n = (b - a)
                .cross(&(c - a))
                .try_normalize(0.0)
                .unwrap_or_default();
            let v = |p: Point3<f64>| stl_io::Vertex::new([p.x as f32, p.y as f32, p.z as f32]);
            stl_io::Triangle {
                normal: stl_io::Normal::new([n.x as f32, n.y as f32, n.z as f32]),
                vertices: [v(a), v(b), v(c)],
            }
        })
        .collect();
    let mut buf = Vec::new();
    stl_io::write_stl(&mut buf, tris.iter()).map_err(write_err(path))?;
    write_atomic(path, &buf).map_err(write_err(path))
}

/// Write an ASCII STL (stl_io writes binary only; ASCII STL is a fixed five-line record).
pub fn write_stl_ascii(mesh: &Mesh, path: &Path) -> Result<(), MeshIoError> {
    use std::fmt::Write;
    let mut s = String::from("solid acetab\n");
    for t in &mesh.triangles {
        let [a, b, c] = t.map(|i| mesh.vertices[i as usize]);
        let n = (b - a)
            .cross(&(c - a))
            .try_normalize(0.0)
            .unwrap_or_default();
        let _ = writeln!(
            s,
            "  facet normal {:e} {:e} {:e}\n    outer loop",
            n.x, n.y, n.z
        );
        for p in [a, b, c] {
            let _ = writeln!(s, "      vertex {:e} {:e} {:e}", p.x, p.y, p.z);
        }
        s.push_str("    endloop\n  endfacet\n");
    }
    s.push_str("endsolid acetab\n");
    write_atomic(path, s.as_bytes()).map_err(write_err(path))
}

/// Write an ASCII PLY with optional per-vertex colour (red, green, blue as uchar).
pub fn write_ply(mesh: &Mesh, colors: Option<&[Rgb]>, path: &Path) -> Result<(), MeshIoError> {
    write_ply_with(mesh, colors, None, path)
}

/// As `write_ply`, with one more per-vertex float property (name, values; NaN where a vertex
/// has none) that a viewer can map to colours itself.
pub fn write_ply_with(
    mesh: &Mesh,
    colors: Option<&[Rgb]>,
    scalar: Option<(&str, &[f64])>,
    path: &Path,
) -> Result<(), MeshIoError> {
    use ply_rs::ply::{
        Addable, DefaultElement, ElementDef, Encoding, Ply, Property, PropertyDef, PropertyType,
        ScalarType,
    };
    let mut ply = Ply::<DefaultElement>::new();
    ply.header.encoding = Encoding::Ascii;
    let mut vdef = ElementDef::new("vertex".to_string());
    for name in ["x", "y", "z"] {
        vdef.properties.add(PropertyDef::new(
            name.to_string(),
            PropertyType::Scalar(ScalarType::Double),
        ));
    }
    if colors.is_some() {
        for name in ["red", "green", "blue"] {
            vdef.properties.add(PropertyDef::new(
                name.to_string(),
                PropertyType::Scalar(ScalarType::UChar),
            ));
        }
    }
    if let Some((name, _)) = scalar {
        vdef.properties.add(PropertyDef::new(
            name.to_string(),
            PropertyType::Scalar(ScalarType::Float),
        ));
    }
    ply.header.elements.add(vdef);
    let mut fdef = ElementDef::new("face".to_string());
    fdef.properties.add(PropertyDef::new(
        "vertex_indices".to_string(),
        PropertyType::List(ScalarType::UChar, ScalarType::Int),
    ));
    ply.header.elements.add(fdef);
    let verts = mesh
        .vertices
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let mut e = DefaultElement::new();
            e.insert("x".into(), Property::Double(p.x));
            e.insert("y".into(), Property::Double(p.y));
            e.insert("z".into(), Property::Double(p.z));
            if let Some(c) = colors.and_then(|c| c.get(i)) {
                e.insert("red".into(), Property::UChar(c[0]));
                e.insert("green".into(), Property::UChar(c[1]));
                e.insert("blue".into(), Property::UChar(c[2]));
            } else if colors.is_some() {
                for k in ["red", "green", "blue"] {
                    e.insert(k.into(), Property::UChar(200));
                }
            }
            if let Some((name, values)) = scalar {
                let v = values.get(i).copied().unwrap_or(f64::NAN);
                e.insert(name.into(), Property::Float(v as f32));
            }
            e
        })
        .collect();
    let faces = mesh
        .triangles
        .iter()
        .map(|t| {
            let mut e = DefaultElement::new();
            e.insert(
                "vertex_indices".into(),
                Property::ListInt(t.iter().map(|&i| i as i32).collect()),
            );
            e
        })
        .collect();
    ply.payload.insert("vertex".into(), verts);
    ply.payload.insert("face".into(), faces);
    let mut buf = Vec::new();
    ply_rs::writer::Writer::new()
        .write_ply(&mut buf, &mut ply)
        .map_err(write_err(path))?;
    write_atomic(path, &buf).map_err(write_err(path))
}

/// Write a Wavefront OBJ (positions and triangles).
pub fn write_obj(mesh: &Mesh, path: &Path) -> Result<(), MeshIoError> {
    use std::fmt::Write;
    let mut s = String::from("# acetab\n");
    for p in &mesh.vertices {
        let _ = writeln!(s, "v {} {} {}", p.x, p.y, p.z);
    }
    for t in &mesh.triangles {
        let _ = writeln!(s, "f {} {} {}", t[0] + 1, t[1] + 1, t[2] + 1);
    }
    write_atomic(path, s.as_bytes()).map_err(write_err(path))
}

/// Write by extension: .stl (binary), .ply or .obj.
pub fn write_mesh(mesh: &Mesh, path: &Path) -> Result<(), MeshIoError> {
    match ext_of(path).as_str() {
        "stl" => write_stl_binary(mesh, path),
        "ply" => write_ply(mesh, None, path),
        "obj" => write_obj(mesh, path),
        ext => Err(MeshIoError::Extension {
            path: path.to_path_buf(),
            ext: ext.to_string(),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::template::hemisphere;

    fn tmpdir(tag: &str) -> tempfile::TempDir {
        tempfile::Builder::new()
            .prefix(&format!("acetab-io-{tag}-"))
            .tempdir()
            .unwrap()
    }

    fn assert_same_geometry(a: &Mesh, b: &Mesh, tol: f64) {
        assert_eq!(a.vertex_count(), b.vertex_count());
        assert_eq!(a.triangles.len(), b.triangles.len());
        assert!((a.area() - b.area()).abs() < tol * a.area());
    }

    #[test]
    fn round_trip_every_format() {
        let m = hemisphere(10.0, 400);
        let tmp = tmpdir("rt");
        let d = tmp.path();
        for name in ["a.obj", "a.ply", "a.stl"] {
            let p = d.join(name);
            write_mesh(&m, &p).unwrap();
            assert_same_geometry(&m, &read_mesh(&p).unwrap(), 1e-5);
        }
        let p = d.join("ascii.stl");
        write_stl_ascii(&m, &p).unwrap();
        assert_same_geometry(&m, &read_mesh(&p).unwrap(), 1e-5);
        let colors = vec![[255u8, 0, 0]; m.vertex_count()];
        let p = d.join("c.ply");
        write_ply(&m, Some(&colors), &p).unwrap();
        let text = std::fs::read_to_string(&p).unwrap();
        assert!(text.contains("property uchar red"));
        assert_same_geometry(&m, &read_mesh(&p).unwrap(), 1e-9);
    }

    /// A binary STL whose header counts fewer triangles than the file holds is refused (it
    /// was read silently without the rest), as is one cut short; the sound file and one with a
    /// few bytes of padding after its triangles are read whole.
    #[test]
    fn binary_stl_size_must_match_its_header() {
        let m = hemisphere(10.0, 400);
        let tmp = tmpdir("stlcount");
        let d = tmp.path();
        let sound = d.join("sound.stl");
        write_stl_binary(&m, &sound).unwrap();
        let bytes = std::fs::read(&sound).unwrap();
        let n = u32::from_le_bytes(bytes[80..84].try_into().unwrap());
        assert_eq!(bytes.len(), 84 + 50 * n as usize);
        assert_eq!(
            read_mesh(&sound).unwrap().triangles.len(),
            m.triangles.len()
        );
        let mut padded = bytes.clone();
        padded.extend_from_slice(&[0u8; 7]);
        let p = d.join("padded.stl");
        std::fs::write(&p, &padded).unwrap();
        assert_eq!(read_mesh(&p).unwrap().triangles.len(), m.triangles.len());

        let mut undercounted = bytes.clone();
        undercounted[80..84].copy_from_slice(&(n - 3).to_le_bytes());
        let p = d.join("undercounted.stl");
        std::fs::write(&p, &undercounted).unwrap();
        let e = read_mesh(&p).unwrap_err().to_string();
        assert!(
            e.contains("undercounted.stl")
                && e.contains(&format!("header says {} triangles", n - 3))
                && e.contains("3 more triangles"),
            "{e}"
        );

        let p = d.join("cut.stl");
        std::fs::write(&p, &bytes[..bytes.len() - 60]).unwrap();
        let e = read_mesh(&p).unwrap_err().to_string();
        assert!(
            e.contains("cut.stl")
                && e.contains(&format!("header says {n} triangles"))
                && e.contains(&format!("has {} bytes", bytes.len() - 60)),
            "{e}"
        );
    }

    #[test]
    fn bad_files_name_the_path() {
        let tmp = tmpdir("bad");
        let d = tmp.path();
        let p = d.join("broken.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nend_header\n1\n",
        )
        .unwrap();
        let e = read_mesh(&p).unwrap_err().to_string();
        assert!(e.contains("broken.ply"), "{e}");
        // A truncated element list: ply-rs's several-line message comes out on one line.
        let p = d.join("short.ply");
        std::fs::write(
            &p,
            "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
             property float z\nend_header\n0 0 0\n1 0 0\n",
        )
        .unwrap();
        let e = read_mesh(&p).unwrap_err().to_string();
        assert!(e.contains("short.ply") && !e.contains('\n'), "{e:?}");
        let e = read_mesh(&d.join("nothing.stl")).unwrap_err().to_string();
        assert!(e.contains("nothing.stl"), "{e}");
        std::fs::write(d.join("x.xyz"), "0 0 0\n").unwrap();
        let e = read_mesh(&d.join("x.xyz")).unwrap_err().to_string();
        assert!(e.contains("unsupported"), "{e}");
        // A folder is named as one.
        let e = read_mesh(d).unwrap_err().to_string();
        assert!(e.contains("a folder, not a mesh file"), "{e}");
        // A path that is not there is named as missing, not as an unsupported extension.
        for missing in ["no-such-folder", "y.xyz"] {
            let e = read_mesh(&d.join(missing)).unwrap_err().to_string();
            assert!(
                e.contains(missing) && e.contains("no such file or folder"),
                "{e}"
            );
        }
    }
}
