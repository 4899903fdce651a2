//! Files in and out: mesh files (STL, PLY, OBJ) and atomic writes, so that a failed run never
//! leaves a half-written file or folder behind.

mod atomic;
mod mesh_file;

pub use atomic::{fill_dir_atomically, write_atomic};
pub use mesh_file::{
    read_mesh, write_mesh, write_obj, write_ply, write_ply_with, write_stl_ascii, write_stl_binary,
    MeshIoError, Rgb,
};
