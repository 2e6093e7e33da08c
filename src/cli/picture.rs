//! `pygmalion picture` and `pygmalion film`: still pictures and short films of statues,
//! rendered on the CPU ([`crate::render`]) — comparison panels for the README, frames for a
//! film-maker, checks for museum staff.
//!
//! * `picture IN.ply --out OUT.png [--fit FIT.json [--bones] [--pose POSE --method M|all]]`:
//!   the statue (with its fitted bones drawn over it when asked) and, with a pose, the statue
//!   re-posed by one method or by every method side by side, all panels at the same scale.
//! * `film IN.ply FIT.json POSE --out DIR [--frames N] [--method M] [--orbit DEG]`: `N`
//!   frames (`DIR/frame_0000.png` …) of the statue moving from its fitted pose to `POSE` with
//!   a smooth ease-in-out, the camera turning by `DEG` degrees; encode them with any video tool
//!   (e.g. `ffmpeg -i DIR/frame_%04d.png film.mp4`).
//!
//! With a fit the camera faces the statue's own front (the fitted root frame's `+Z`, up its
//! `+Y`); without one it looks along `−Z` with `+Y` up (the data set's convention).

use crate::anatomy::Skeleton;
use crate::anatomy::pose::{ease, interpolate};
use crate::cloud::PointCloud;
use crate::error::{Error, Result};
use crate::math::Vec3;
use crate::render::{Camera, Image, RenderOptions, overlay_segments, overlay_spheres, render};
use crate::skinning::{Binding, Method, Scratch};
use std::path::Path;
use std::time::Instant;

/// Bone overlay colour.
const BONE_COLOR: [u8; 3] = [255, 140, 40];

/// Arguments of `picture`.
pub struct PictureArgs<'a> {
    pub input: &'a Path,
    pub out: &'a Path,
    pub fit: Option<&'a Path>,
    pub pose: Option<&'a str>,
    /// A method name or `all`.
    pub method: &'a str,
    pub bones: bool,
    pub template: Option<&'a str>,
    pub width: u32,
    pub height: u32,
    /// Extra turn of the camera about the statue's up axis, degrees.
    pub turn_deg: f32,
}

/// Arguments of `film`.
pub struct FilmArgs<'a> {
    pub input: &'a Path,
    pub fit: &'a Path,
    pub pose: &'a str,
    pub method: &'a str,
    pub out_dir: &'a Path,
    pub frames: usize,
    pub orbit_deg: f32,
    pub template: Option<&'a str>,
    pub width: u32,
    pub height: u32,
}

fn methods(name: &str) -> Result<Vec<Method>> {
    if name.eq_ignore_ascii_case("all") {
        Ok(Method::ALL.to_vec())
    } else {
        Ok(vec![name.parse()?])
    }
}

fn read_with_normals(input: &Path) -> Result<PointCloud> {
    Ok(super::read_with_normals(input, false)?.0)
}

/// The camera for a set of clouds seen from the fitted statue's front (or along −Z).
fn camera_for(clouds: &[&[Vec3]], fitted: Option<&Skeleton>, aspect: f32, turn: f32) -> Camera {
    let (front, up) = match fitted {
        Some(s) => (s.root_rotation * Vec3::Z, s.up()),
        None => (Vec3::Z, Vec3::Y),
    };
    let (front, up) = if turn != 0.0 {
        let q = crate::math::Quat::from_axis_angle(up, turn.to_radians());
        (q * front, up)
    } else {
        (front, up)
    };
    let mut lo = Vec3::splat(f32::INFINITY);
    let mut hi = Vec3::splat(f32::NEG_INFINITY);
    for c in clouds {
        for p in c.iter().filter(|p| p.is_finite()) {
            lo = lo.min(*p);
            hi = hi.max(*p);
        }
    }
    if !lo.is_finite() {
        lo = Vec3::ZERO;
        hi = Vec3::ONE;
    }
    Camera::frame_aspect(lo, hi, -front, up, aspect)
}

fn draw_bones(img: &mut Image, camera: &Camera, skel: &Skeleton) {
    let posed = skel.pose();
    let segs: Vec<(Vec3, Vec3)> = posed.bones.iter().map(|b| (b.c1, b.c2)).collect();
    let spheres: Vec<(Vec3, f32)> = posed
        .bones
        .iter()
        .flat_map(|b| [(b.c1, b.r1), (b.c2, b.r2)])
        .collect();
    overlay_spheres(img, camera, &spheres, BONE_COLOR);
    overlay_segments(img, camera, &segs, BONE_COLOR, 2.0);
}

/// Runs `picture`.
pub fn run_picture(a: &PictureArgs) -> Result<()> {
    let methods = methods(a.method)?;
    if a.pose.is_some() && a.fit.is_none() {
        return Err(Error::input(
            "picture: --pose needs --fit (the statue's fitted skeleton)",
        ));
    }
    if a.bones && a.fit.is_none() {
        return Err(Error::input("picture: --bones needs --fit"));
    }
    let fits = match (a.fit, a.pose) {
        (Some(fit), Some(pose)) => Some(super::repose::target(fit, pose, None, a.template)?),
        (Some(fit), None) => {
            let template = a
                .template
                .map(|t| crate::anatomy::Template::resolve(t).map(std::sync::Arc::new))
                .transpose()?;
            let s = Skeleton::load_json(fit, template)?;
            Some((s.clone(), s))
        }
        _ => None,
    };
    let cloud = read_with_normals(a.input)?;
    let mut panels: Vec<(String, PointCloud)> = vec![("statue".into(), cloud.clone())];
    if let (Some((fitted, target)), Some(_)) = (&fits, a.pose) {
        let start = Instant::now();
        let binding = Binding::new_on_base(&cloud, fitted)?;
        println!(
            "bound {} points in {:.3} s",
            cloud.len(),
            start.elapsed().as_secs_f64()
        );
        for m in &methods {
            let mut out = binding.deform_cloud(target, *m)?;
            out.colors = cloud.colors.clone();
            panels.push((m.name().to_string(), out));
        }
    }
    let all: Vec<&[Vec3]> = panels.iter().map(|(_, c)| c.positions.as_slice()).collect();
    let aspect = a.width as f32 / a.height as f32;
    let camera = camera_for(&all, fits.as_ref().map(|f| &f.0), aspect, a.turn_deg);
    let opts = RenderOptions {
        width: a.width,
        height: a.height,
        ..Default::default()
    };
    let mut images = Vec::new();
    for (i, (_, c)) in panels.iter().enumerate() {
        let mut img = render(
            &c.positions,
            c.normals.as_deref(),
            c.colors.as_deref(),
            &camera,
            &opts,
        );
        if a.bones
            && let Some((fitted, target)) = &fits
        {
            draw_bones(&mut img, &camera, if i == 0 { fitted } else { target });
        }
        images.push(img);
    }
    let sheet = Image::hstack(&images, 8, opts.background);
    sheet.save_png(a.out)?;
    println!(
        "{} → {} ({} panel(s): {})",
        a.input.display(),
        a.out.display(),
        panels.len(),
        panels
            .iter()
            .map(|(n, _)| n.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    );
    Ok(())
}

/// Runs `film`.
pub fn run_film(a: &FilmArgs) -> Result<()> {
    let method: Method = a.method.parse()?;
    if a.frames == 0 || a.frames > 10_000 {
        return Err(Error::input("film: --frames must be between 1 and 10000"));
    }
    let (fitted, target) = super::repose::target(a.fit, a.pose, None, a.template)?;
    let cloud = read_with_normals(a.input)?;
    let binding = Binding::new_on_base(&cloud, &fitted)?;
    std::fs::create_dir_all(a.out_dir).map_err(|e| Error::Io {
        path: a.out_dir.to_path_buf(),
        source: e,
    })?;
    let end = binding.deform_cloud(&target, method)?;
    let aspect = a.width as f32 / a.height as f32;
    let base = camera_for(
        &[&cloud.positions, &end.positions],
        Some(&fitted),
        aspect,
        0.0,
    );
    let opts = RenderOptions {
        width: a.width,
        height: a.height,
        ..Default::default()
    };
    let mut scratch = Scratch::default();
    let mut pos = vec![Vec3::ZERO; binding.len()];
    let mut nrm = vec![Vec3::ZERO; binding.len()];
    let start = Instant::now();
    for f in 0..a.frames {
        let s = if a.frames == 1 {
            1.0
        } else {
            f as f32 / (a.frames - 1) as f32
        };
        let skel = interpolate(&fitted, &target, ease(s));
        binding.deform(&skel, method, &mut scratch, &mut pos, &mut nrm)?;
        let camera = base.orbit((a.orbit_deg * s).to_radians());
        let img = render(&pos, Some(&nrm), cloud.colors.as_deref(), &camera, &opts);
        img.save_png(a.out_dir.join(format!("frame_{f:04}.png")))?;
    }
    println!(
        "{}: {} frames of '{}' ({method}) in {:.1} s → {}/frame_0000.png …",
        a.input.display(),
        a.frames,
        a.pose,
        start.elapsed().as_secs_f64(),
        a.out_dir.display()
    );
    Ok(())
}
