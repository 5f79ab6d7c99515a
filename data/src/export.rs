//! Writing a model as Wavefront OBJ + MTL in any unit and up axis, as SketchUp, 3ds Max or
//! Revit would: the way to test the importers' frame detection ([`crate::import::frame`]) on
//! buildings of any size (`portico generate --units cm --up z -o building.obj`). Each file is
//! written whole beside its name, then renamed into place.

use crate::error::{DataError, Result};
use crate::frame::SourceFrame;
use crate::model::Model;
use glam::{DVec3, Vec3};
use std::io::Write;
use std::path::Path;

/// Writes every instance's finest LOD, placed, to `obj` (and its materials' colours to the
/// `.mtl` beside it), in `frame`'s unit and up axis. Errors name the file.
pub fn write_obj(model: &Model, frame: &SourceFrame, obj: &Path) -> Result<()> {
    let mtl = obj.with_extension("mtl");
    let mtl_name = mtl
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let to_file = frame.to_metres_y_up().inverse();
    let turn = to_file.to_scale_rotation_translation().1;
    let origin = DVec3::from(model.origin);
    let dir = obj
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| DataError::io(dir, e))?;
    let mut out = std::io::BufWriter::new(tmp);
    let mut text = format!(
        "# written by portico in {}, {} up\nmtllib {mtl_name}\n",
        frame.unit.name(),
        frame.up.symbol().to_ascii_uppercase()
    );
    let mut base = 1usize;
    for (k, inst) in model.instances.iter().enumerate() {
        let Some(mesh) = model
            .defs
            .get(inst.def as usize)
            .and_then(|d| d.lods.first())
        else {
            continue;
        };
        let m = inst.transform.as_dmat4();
        // Normals by the inverse transpose; a mirroring transform turns the winding too.
        let normals = m.inverse().transpose();
        let mirrored = m.determinant() < 0.0;
        text.push_str(&format!(
            "o {}_{k}\nusemtl m{}\n",
            clean(&inst.name),
            inst.material
        ));
        for v in &mesh.vertices {
            let p = to_file
                .transform_point3(m.transform_point3(Vec3::from(v.position).as_dvec3()) + origin);
            text.push_str(&format!("v {:.6} {:.6} {:.6}\n", p.x, p.y, p.z));
        }
        for v in &mesh.vertices {
            let n =
                (turn * normals.transform_vector3(v.normal_f32().as_dvec3())).normalize_or_zero();
            text.push_str(&format!("vn {:.4} {:.4} {:.4}\n", n.x, n.y, n.z));
        }
        for t in mesh.indices.chunks_exact(3) {
            let [a, mut b, mut c] = [t[0], t[1], t[2]].map(|i| i as usize + base);
            if mirrored {
                std::mem::swap(&mut b, &mut c);
            }
            text.push_str(&format!("f {a}//{a} {b}//{b} {c}//{c}\n"));
        }
        base += mesh.vertices.len();
        if text.len() > 1 << 20 {
            out.write_all(text.as_bytes())
                .map_err(|e| DataError::io(obj, e))?;
            text.clear();
        }
    }
    out.write_all(text.as_bytes())
        .and_then(|_| out.flush())
        .map_err(|e| DataError::io(obj, e))?;
    let tmp = out
        .into_inner()
        .map_err(|e| DataError::io(obj, e.into_error()))?;
    let mut lib = String::new();
    for (i, m) in model.materials.iter().enumerate() {
        let [r, g, b, a] = m.base_color;
        lib.push_str(&format!(
            "newmtl m{i}\nKd {r:.4} {g:.4} {b:.4}\nd {a:.4}\n\n"
        ));
    }
    // The library first, then the model that names it; both readable by other tools and
    // users, as any model file (a temporary file is private).
    let mut lib_tmp = tempfile::NamedTempFile::new_in(dir).map_err(|e| DataError::io(dir, e))?;
    lib_tmp
        .write_all(lib.as_bytes())
        .map_err(|e| DataError::io(&mtl, e))?;
    readable(lib_tmp.as_file()).map_err(|e| DataError::io(&mtl, e))?;
    lib_tmp
        .persist(&mtl)
        .map_err(|e| DataError::io(&mtl, e.error))?;
    readable(tmp.as_file()).map_err(|e| DataError::io(obj, e))?;
    tmp.persist(obj).map_err(|e| DataError::io(obj, e.error))?;
    Ok(())
}

/// Makes a file world-readable (0644) where permissions exist.
fn readable(file: &std::fs::File) -> std::io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        file.set_permissions(std::fs::Permissions::from_mode(0o644))?;
    }
    #[cfg(not(unix))]
    let _ = file;
    Ok(())
}

/// A name OBJ can carry on one line without spaces.
fn clean(name: &str) -> String {
    let s: String = name
        .chars()
        .map(|c| {
            if c.is_whitespace() || c.is_control() {
                '_'
            } else {
                c
            }
        })
        .collect();
    if s.is_empty() { "object".into() } else { s }
}
