//! Saving and loading a [`Binding`] (so a kiosk starts at once on a statue it has seen).
//!
//! Format (little-endian): the magic `PYGBIND3`, the template name, the fitted skeleton's raw
//! state (root position and rotation, block scale, per bone rotation, length and radii — raw
//! `f32`s, so the reloaded skeleton is bit-identical), the point count, then every per-point
//! array of [`super::binding::PointData`] in declaration order, then the base's point count
//! (`u64`) and its indices (`u32`, increasing), then the count of bones left out
//! ([`Binding::lost`], `u64`) and their indices (`u32`, increasing). The per-bone part and the
//! fitted pose's baseline tables are recomputed from the skeleton (a pure function of it), so
//! a reloaded binding deforms exactly like the original. The file is written to a temporary
//! sibling and renamed; loading checks every index and count against the file's size and the
//! template, and names the file in every error.

use super::binding::{Binding, NONE, PointData};
use crate::anatomy::{BoneState, Skeleton, Template};
use crate::error::{Error, Result};
use crate::math::{Quat, Vec3};
use std::path::Path;
use std::sync::Arc;

const MAGIC: &[u8; 8] = b"PYGBIND3";

struct Writer(Vec<u8>);

impl Writer {
    fn u32(&mut self, v: u32) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn u64(&mut self, v: u64) {
        self.0.extend_from_slice(&v.to_le_bytes());
    }
    fn f32s(&mut self, v: &[f32]) {
        for x in v {
            self.0.extend_from_slice(&x.to_le_bytes());
        }
    }
    fn vec3s(&mut self, v: &[Vec3]) {
        for x in v {
            self.f32s(&x.to_array());
        }
    }
}

struct Reader<'a> {
    bytes: &'a [u8],
    at: usize,
    path: &'a Path,
}

impl<'a> Reader<'a> {
    fn err(&self, what: &str) -> Error {
        Error::config(self.path, format!("not a valid binding file: {what}"))
    }
    fn take(&mut self, n: usize) -> Result<&'a [u8]> {
        let end = self
            .at
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or_else(|| self.err("truncated"))?;
        let s = &self.bytes[self.at..end];
        self.at = end;
        Ok(s)
    }
    fn u32(&mut self) -> Result<u32> {
        Ok(u32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    fn u64(&mut self) -> Result<u64> {
        Ok(u64::from_le_bytes(
            self.take(8)?.try_into().expect("8 bytes"),
        ))
    }
    fn f32(&mut self) -> Result<f32> {
        Ok(f32::from_le_bytes(
            self.take(4)?.try_into().expect("4 bytes"),
        ))
    }
    fn f32s(&mut self, n: usize) -> Result<Vec<f32>> {
        let b = self.take(n.checked_mul(4).ok_or_else(|| self.err("count"))?)?;
        Ok(b.chunks_exact(4)
            .map(|c| f32::from_le_bytes(c.try_into().expect("4 bytes")))
            .collect())
    }
    fn vec3s(&mut self, n: usize) -> Result<Vec<Vec3>> {
        let v = self.f32s(n.checked_mul(3).ok_or_else(|| self.err("count"))?)?;
        Ok(v.chunks_exact(3).map(Vec3::from_slice).collect())
    }
}

impl Binding {
    /// Writes the binding to `path` (see the module docs for the format).
    pub fn save(&self, path: impl AsRef<Path>) -> Result<()> {
        let path = path.as_ref();
        let s = &self.fitted;
        let pts = &self.points;
        let mut w = Writer(Vec::with_capacity(64 + self.len() * 96));
        w.0.extend_from_slice(MAGIC);
        let name = s.template.name.as_bytes();
        w.u32(name.len() as u32);
        w.0.extend_from_slice(name);
        w.f32s(&s.root_position.to_array());
        w.f32s(&s.root_rotation.to_array());
        w.f32s(&[s.block_scale]);
        w.u32(s.bones.len() as u32);
        for b in &s.bones {
            w.f32s(&b.rotation.to_array());
            w.f32s(&[b.length, b.r1, b.r2]);
        }
        w.u64(self.len() as u64);
        for b in &pts.bone {
            w.0.extend_from_slice(&b.to_le_bytes());
        }
        w.0.extend_from_slice(&pts.part);
        w.f32s(&pts.s);
        w.vec3s(&pts.dir);
        w.f32s(&pts.height);
        w.vec3s(&pts.normal);
        w.vec3s(&pts.position);
        for b in &pts.partner {
            w.0.extend_from_slice(&b.to_le_bytes());
        }
        w.f32s(&pts.weight);
        for c in &pts.bl_cell {
            w.u32(*c);
        }
        for uv in &pts.bl_uv {
            w.f32s(uv);
        }
        w.f32s(&pts.bl_h);
        w.vec3s(&pts.bl_res);
        w.vec3s(&pts.bl_n);
        w.u64(self.base.len() as u64);
        for &i in &self.base {
            w.u32(i);
        }
        let lost: Vec<u32> = (0..self.lost.len() as u32)
            .filter(|&b| self.lost[b as usize])
            .collect();
        w.u64(lost.len() as u64);
        for b in lost {
            w.u32(b);
        }
        let tmp = path.with_extension("tmp-binding");
        std::fs::write(&tmp, &w.0)
            .and_then(|_| std::fs::rename(&tmp, path))
            .map_err(|e| {
                let _ = std::fs::remove_file(&tmp);
                Error::Io {
                    path: path.to_path_buf(),
                    source: e,
                }
            })
    }

    /// Reads a binding written by [`Binding::save`] for a statue fitted with `template`.
    pub fn load(path: impl AsRef<Path>, template: Arc<Template>) -> Result<Binding> {
        let path = path.as_ref();
        let bytes = std::fs::read(path).map_err(|e| Error::Io {
            path: path.to_path_buf(),
            source: e,
        })?;
        let mut r = Reader {
            bytes: &bytes,
            at: 0,
            path,
        };
        if r.take(8)? != MAGIC {
            return Err(r.err("wrong magic number"));
        }
        let name_len = r.u32()? as usize;
        let name = String::from_utf8_lossy(r.take(name_len)?).into_owned();
        if name != template.name {
            return Err(Error::config(
                path,
                format!(
                    "binding made with template '{name}', not '{}'",
                    template.name
                ),
            ));
        }
        let root_position = Vec3::from_slice(&r.f32s(3)?);
        let root_rotation = Quat::from_slice(&r.f32s(4)?);
        let block_scale = r.f32()?;
        let nb = r.u32()? as usize;
        if nb != template.bones.len() {
            return Err(r.err("bone count differs from the template"));
        }
        let mut bones = Vec::with_capacity(nb);
        for _ in 0..nb {
            let q = r.f32s(4)?;
            let v = r.f32s(3)?;
            bones.push(BoneState {
                rotation: Quat::from_slice(&q),
                length: v[0],
                r1: v[1],
                r2: v[2],
            });
        }
        let fitted = Skeleton {
            template,
            root_position,
            root_rotation,
            block_scale,
            bones,
        };
        super::binding::check_skeleton(&fitted, &path.display().to_string())?;
        let n = r.u64()?;
        // At least 90 bytes per point follow: refuse counts the file cannot hold before
        // allocating anything.
        if n == 0 || n > ((bytes.len() - r.at) / 90) as u64 {
            return Err(r.err("point count does not match the file size"));
        }
        let n = n as usize;
        let u16s = |r: &mut Reader| -> Result<Vec<u16>> {
            Ok(r.take(2 * n)?
                .chunks_exact(2)
                .map(|c| u16::from_le_bytes([c[0], c[1]]))
                .collect())
        };
        let mut pts = PointData {
            bone: u16s(&mut r)?,
            part: r.take(n)?.to_vec(),
            ..Default::default()
        };
        pts.s = r.f32s(n)?;
        pts.dir = r.vec3s(n)?;
        pts.height = r.f32s(n)?;
        pts.normal = r.vec3s(n)?;
        pts.position = r.vec3s(n)?;
        pts.partner = u16s(&mut r)?;
        pts.weight = r.f32s(n)?;
        pts.bl_cell = (0..n).map(|_| r.u32()).collect::<Result<_>>()?;
        pts.bl_uv = r
            .f32s(2 * n)?
            .chunks_exact(2)
            .map(|c| [c[0], c[1]])
            .collect();
        pts.bl_h = r.f32s(n)?;
        pts.bl_res = r.vec3s(n)?;
        pts.bl_n = r.vec3s(n)?;
        let nbase = r.u64()?;
        if nbase > n as u64 {
            return Err(r.err("more base points than points"));
        }
        let base: Vec<u32> = (0..nbase).map(|_| r.u32()).collect::<Result<_>>()?;
        if base.windows(2).any(|w| w[0] >= w[1]) || base.last().is_some_and(|&i| i as usize >= n) {
            return Err(r.err("base indices out of order or out of range"));
        }
        let nlost = r.u64()?;
        if nlost >= nb as u64 {
            return Err(r.err("more lost bones than the skeleton can lose"));
        }
        let lost_bones: Vec<u32> = (0..nlost).map(|_| r.u32()).collect::<Result<_>>()?;
        if lost_bones.windows(2).any(|w| w[0] >= w[1])
            || lost_bones.last().is_some_and(|&b| b as usize >= nb)
        {
            return Err(r.err("lost bone indices out of order or out of range"));
        }
        let mut lost = vec![false; if nlost > 0 { nb } else { 0 }];
        for b in lost_bones {
            lost[b as usize] = true;
        }
        if r.at != bytes.len() {
            return Err(r.err("trailing bytes"));
        }
        let mut b = Binding::from_parts(fitted, pts);
        b.base = base;
        b.lost = lost;
        b.validate().map_err(|m| r.err(&m))?;
        Ok(b)
    }

    /// Checks the indices and values of a loaded binding.
    fn validate(&self) -> std::result::Result<(), String> {
        let nb = self.bones.len();
        let cells = super::baseline::GRID_NT * super::baseline::GRID_NPSI * nb;
        let p = &self.points;
        if p.bone.iter().any(|&b| b as usize >= nb) {
            return Err("a point's bone index is out of range".into());
        }
        if p.partner.iter().any(|&b| b != NONE && b as usize >= nb) {
            return Err("a point's partner bone is out of range".into());
        }
        if p.part.iter().any(|&x| x > 2) {
            return Err("a point's part is invalid".into());
        }
        if p.bl_cell.iter().any(|&c| {
            c != super::baseline::NO_CELL && c as usize + super::baseline::GRID_NPSI + 1 > cells
        }) {
            return Err("a point's baseline cell is out of range".into());
        }
        let finite =
            p.s.iter()
                .chain(&p.height)
                .chain(&p.weight)
                .chain(&p.bl_h)
                .all(|x| x.is_finite())
                && p.dir
                    .iter()
                    .chain(&p.normal)
                    .chain(&p.position)
                    .chain(&p.bl_res)
                    .chain(&p.bl_n)
                    .all(|v| v.is_finite())
                && p.bl_uv
                    .iter()
                    .all(|uv| uv[0].is_finite() && uv[1].is_finite());
        if !finite {
            return Err("non-finite values".into());
        }
        Ok(())
    }
}
