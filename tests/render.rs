//! Tests of `pygmalion::render`: the PNG encoder and its checksums (against published check
//! values and a round trip through the subset decoder), the splat renderer on an analytic
//! sphere (coverage of the projected disk, lit versus unlit side), determinism across thread
//! counts, degenerate input, the camera, the overlays, and a bundled statue.

use std::f32::consts::{FRAC_PI_2, TAU};

use pygmalion::cloud::ply::read_ply;
use pygmalion::math::Vec3;
use pygmalion::render::png::{self, adler32, crc32};
use pygmalion::render::{Camera, Image, RenderOptions, overlay_segments, overlay_spheres, render};
use pygmalion::rng::Rng;

use crate::common::{scratch, statues_dir};

// ------------------------------------------------------------------------------------------
// Helpers
// ------------------------------------------------------------------------------------------

const BG: [u8; 3] = [0, 0, 255];

/// `n` random points on the sphere of `radius` around the origin, with outward normals.
fn sphere(n: usize, radius: f32, seed: u64) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut rng = Rng::new(seed);
    (0..n)
        .map(|_| {
            let u = rng.unit_vector();
            (u * radius, u)
        })
        .unzip()
}

fn opts(size: u32) -> RenderOptions {
    RenderOptions {
        width: size,
        height: size,
        background: BG,
        ..RenderOptions::default()
    }
}

/// Mean grey level of the non-background pixels of `img` that satisfy `keep(x, y)`, and how
/// many there are.
fn mean_level(img: &Image, keep: impl Fn(u32, u32) -> bool) -> (f64, usize) {
    let (mut sum, mut n) = (0.0, 0);
    for y in 0..img.height {
        for x in 0..img.width {
            let c = img.get(x, y).unwrap();
            if c != BG && keep(x, y) {
                sum += (c[0] as f64 + c[1] as f64 + c[2] as f64) / 3.0;
                n += 1;
            }
        }
    }
    (sum / n.max(1) as f64, n)
}

/// Fractions of covered (non-background) pixels inside the disk of `radius` pixels around
/// the image centre and outside `outer` times that radius.
fn coverage(img: &Image, radius: f32, outer: f32) -> (f64, f64) {
    let (cx, cy) = (img.width as f32 / 2.0, img.height as f32 / 2.0);
    let (mut inside, mut n_in, mut outside, mut n_out) = (0usize, 0usize, 0usize, 0usize);
    for y in 0..img.height {
        for x in 0..img.width {
            let d = ((x as f32 + 0.5 - cx).powi(2) + (y as f32 + 0.5 - cy).powi(2)).sqrt();
            let covered = img.get(x, y).unwrap() != BG;
            if d <= radius {
                n_in += 1;
                inside += covered as usize;
            } else if d > outer * radius {
                n_out += 1;
                outside += covered as usize;
            }
        }
    }
    (inside as f64 / n_in as f64, outside as f64 / n_out as f64)
}

fn be32(b: &[u8]) -> u32 {
    u32::from_be_bytes([b[0], b[1], b[2], b[3]])
}

// ------------------------------------------------------------------------------------------
// PNG
// ------------------------------------------------------------------------------------------

#[test]
fn checksums_match_published_check_values() {
    assert_eq!(crc32(b"123456789"), 0xCBF4_3926);
    assert_eq!(crc32(b""), 0);
    assert_eq!(adler32(b"Wikipedia"), 0x11E6_0398);
    assert_eq!(adler32(b""), 1);
    // Long input: the Adler sums are reduced in blocks; compare with the plain definition.
    let data: Vec<u8> = (0..200_000u32).map(|i| (i * 7919 % 251) as u8).collect();
    let (mut a, mut b) = (1u64, 0u64);
    for &x in &data {
        a = (a + x as u64) % 65_521;
        b = (b + a) % 65_521;
    }
    assert_eq!(adler32(&data), ((b << 16) | a) as u32);
}

#[test]
fn png_header_of_a_one_pixel_image() {
    let bytes = Image::new(1, 1, [10, 20, 30]).to_png_bytes();
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n");
    assert_eq!(be32(&bytes[8..]), 13, "IHDR length");
    assert_eq!(&bytes[12..16], b"IHDR");
    assert_eq!(&bytes[16..29], &[0, 0, 0, 1, 0, 0, 0, 1, 8, 2, 0, 0, 0]);
    // The CRC of this IHDR (1×1, 8-bit RGB) is a well-known constant (also zlib.crc32).
    assert_eq!(be32(&bytes[29..]), 0x9077_53DE);
    // The zlib stream of the single IDAT: header, one final stored block of 4 bytes (filter
    // byte and one pixel), Adler-32.
    assert_eq!(&bytes[37..41], b"IDAT");
    let len = be32(&bytes[33..]) as usize;
    let zlib = &bytes[41..41 + len];
    assert_eq!(
        zlib,
        &[
            0x78, 0x01, 0x01, 4, 0, 0xFB, 0xFF, 0, 10, 20, 30, 0x00, 0x68, 0x00, 0x3D
        ][..]
    );
    assert_eq!(png::inflate_stored(zlib).unwrap(), vec![0, 10, 20, 30]);
    assert_eq!(&bytes[bytes.len() - 8..bytes.len() - 4], b"IEND");
    assert_eq!(be32(&bytes[bytes.len() - 4..]), 0xAE42_6082, "CRC of IEND");
}

#[test]
fn png_round_trip_through_file_with_many_stored_blocks() {
    // 211 × 157 RGB is 99,580 bytes of pixels (+157 filter bytes): two stored blocks.
    let (w, h) = (211u32, 157u32);
    let mut img = Image::new(w, h, [0, 0, 0]);
    for y in 0..h {
        for x in 0..w {
            img.set(x, y, [(x * 3) as u8, (y * 5) as u8, ((x ^ y) * 7) as u8]);
        }
    }
    let bytes = img.to_png_bytes();
    // Raw pixels + filter bytes + per-block and chunk overhead: stored means no compression.
    let raw = (3 * w as usize + 1) * h as usize;
    assert!(
        bytes.len() > raw && bytes.len() < raw + 100,
        "{}",
        bytes.len()
    );
    assert_eq!(be32(&bytes[16..]), w);
    assert_eq!(be32(&bytes[20..]), h);
    assert_eq!(&bytes[24..29], &[8, 2, 0, 0, 0]);
    assert_eq!(be32(&bytes[29..]), crc32(&bytes[12..29]), "IHDR CRC");

    let (dw, dh, rgb) = png::decode(&bytes).unwrap();
    assert_eq!((dw, dh), (w, h));
    assert_eq!(rgb, img.rgb);

    let dir = scratch("render_png_round_trip");
    let path = dir.join("pattern.png");
    img.save_png(&path).unwrap();
    assert_eq!(std::fs::read(&path).unwrap(), bytes);
    assert_eq!(Image::load_png(&path).unwrap(), img);
    // Only the final file is left (the temporary sibling was renamed).
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names, vec![std::ffi::OsString::from("pattern.png")]);
    // Saving into a missing folder is an Io error naming the path; so is an empty image.
    let missing = dir.join("no/such/dir/x.png");
    match img.save_png(&missing) {
        Err(pygmalion::Error::Io { path, .. }) => assert_eq!(path, missing),
        other => panic!("{other:?}"),
    }
    assert!(matches!(
        Image::new(0, 5, BG).save_png(dir.join("empty.png")),
        Err(pygmalion::Error::Io { .. })
    ));
}

#[test]
fn png_decoder_refuses_what_it_does_not_support() {
    let good = Image::new(3, 2, [1, 2, 3]).to_png_bytes();
    assert!(png::decode(&good).is_ok());
    // A flipped pixel byte breaks the IDAT CRC.
    let mut bad = good.clone();
    let n = bad.len();
    bad[n - 20] ^= 0x40;
    assert!(png::decode(&bad).is_err());
    assert!(png::decode(&good[..good.len() - 12]).is_err(), "no IEND");
    assert!(png::decode(b"GIF89a").is_err());
    // A fixed-Huffman (compressed) deflate block: an empty final block is 03 00.
    let compressed = [0x78, 0x01, 0x03, 0x00, 0x00, 0x00, 0x00, 0x01];
    let err = png::inflate_stored(&compressed).unwrap_err().to_string();
    assert!(err.contains("not supported"), "{err}");
}

// ------------------------------------------------------------------------------------------
// Image
// ------------------------------------------------------------------------------------------

#[test]
fn hstack_places_panels_side_by_side() {
    let a = Image::new(3, 4, [255, 0, 0]);
    let b = Image::new(2, 2, [0, 255, 0]);
    let s = Image::hstack(&[a, b], 1, [9, 9, 9]);
    assert_eq!((s.width, s.height), (6, 4));
    assert_eq!(s.rgb.len(), 6 * 4 * 3);
    assert_eq!(s.get(0, 0), Some([255, 0, 0]));
    assert_eq!(s.get(2, 3), Some([255, 0, 0]));
    assert_eq!(s.get(3, 0), Some([9, 9, 9]), "gap");
    assert_eq!(
        s.get(4, 0),
        Some([9, 9, 9]),
        "above the centred short panel"
    );
    assert_eq!(s.get(4, 1), Some([0, 255, 0]));
    assert_eq!(s.get(5, 2), Some([0, 255, 0]));
    assert_eq!(s.get(5, 3), Some([9, 9, 9]));
    assert_eq!(s.get(6, 0), None);
    assert_eq!(Image::hstack(&[], 4, BG).rgb.len(), 0);
}

// ------------------------------------------------------------------------------------------
// Camera
// ------------------------------------------------------------------------------------------

#[test]
fn camera_frames_and_orbits() {
    let (lo, hi) = (Vec3::new(-1.0, 0.0, -0.5), Vec3::new(1.0, 4.0, 0.5));
    let cam = Camera::front(lo, hi, 1.0);
    assert_eq!(cam.fov_y_deg, 0.0);
    assert!((cam.target - Vec3::new(0.0, 2.0, 0.0)).length() < 1e-6);
    assert!(cam.eye.z > hi.z && cam.eye.x.abs() < 1e-5, "{:?}", cam.eye);
    // The box (4 tall) fits with a small margin; all corners project inside the picture.
    assert!(cam.ortho_height > 4.0 && cam.ortho_height < 4.5);
    for i in 0..8 {
        let p = Vec3::new(
            if i & 1 == 0 { lo.x } else { hi.x },
            if i & 2 == 0 { lo.y } else { hi.y },
            if i & 4 == 0 { lo.z } else { hi.z },
        );
        for c in [cam, cam.orbit(1.0), cam.with_fov(30.0)] {
            let (s, depth) = c.project(p, 100, 100).unwrap();
            assert!(depth > 0.0);
            assert!(
                s.x > 0.0 && s.x < 100.0 && s.y > 0.0 && s.y < 100.0,
                "{s:?}"
            );
        }
    }
    // Top of the box is at the top of the picture (y down).
    let (top, _) = cam.project(Vec3::new(0.0, 4.0, 0.0), 100, 100).unwrap();
    assert!(top.y < 10.0, "{top:?}");
    // A wide picture fits the width instead.
    let wide = Camera::frame_aspect(lo, hi, -Vec3::Z, Vec3::Y, 0.25);
    assert!(wide.ortho_height > 8.0);
    // A quarter turn counter-clockwise seen from above takes the eye from +Z to +X.
    let d = cam.eye - cam.target;
    let q = cam.orbit(FRAC_PI_2);
    assert!((q.eye - cam.target - Vec3::new(d.z, 0.0, 0.0)).length() < 1e-4 * d.length());
    assert!((cam.orbit(TAU).eye - cam.eye).length() < 1e-4 * d.length());
    // Perspective keeps the target plane's framing.
    let p = cam.with_fov(40.0);
    let (edge, _) = p.project(Vec3::new(0.0, 4.0, 0.0), 100, 100).unwrap();
    assert!((edge.y - top.y).abs() < 0.5, "{edge:?} {top:?}");
    // Points behind the eye do not project.
    assert!(p.project(p.eye - (p.target - p.eye), 100, 100).is_none());
    // Framing in perspective: every corner inside, the outermost at 1 / margin of the way
    // from the centre to the picture's edge.
    for fov in [20.0, 60.0] {
        for aspect in [0.5, 2.0] {
            let view = Vec3::new(-1.0, -0.3, -0.7);
            let c = Camera::frame_fov(lo, hi, view, Vec3::Y, aspect, fov);
            assert_eq!(c.fov_y_deg, fov);
            let (w, h) = ((200.0 * aspect) as u32, 200u32);
            let (cx, cy) = (w as f32 / 2.0, h as f32 / 2.0);
            let mut worst = 0.0f32;
            for i in 0..8 {
                let p = Vec3::new(
                    if i & 1 == 0 { lo.x } else { hi.x },
                    if i & 2 == 0 { lo.y } else { hi.y },
                    if i & 4 == 0 { lo.z } else { hi.z },
                );
                let (s, _) = c.project(p, w, h).unwrap();
                worst = worst
                    .max(((s.x - cx) / cx).abs())
                    .max(((s.y - cy) / cy).abs());
            }
            let tight = 1.0 / pygmalion::render::camera::FRAME_MARGIN;
            assert!(
                (worst - tight).abs() < 1e-3,
                "fov {fov} aspect {aspect}: {worst}"
            );
        }
    }
}

// ------------------------------------------------------------------------------------------
// Rendering
// ------------------------------------------------------------------------------------------

#[test]
fn sphere_covers_its_projected_disk() {
    let (pos, nrm) = sphere(20_000, 1.0, 1);
    let size = 256;
    let o = opts(size);
    let cam = Camera::frame(Vec3::splat(-1.0), Vec3::splat(1.0), -Vec3::Z, Vec3::Y);
    for (normals, edl) in [
        (Some(&nrm[..]), true),
        (None, true),
        (Some(&nrm[..]), false),
    ] {
        let img = render(&pos, normals, None, &cam, &RenderOptions { edl, ..o });
        let radius = size as f32 / cam.ortho_height; // unit sphere, pixels per unit
        let (inside, outside) = coverage(&img, radius, 1.1);
        assert!(inside > 0.95, "inside {inside}");
        assert!(outside < 0.01, "outside {outside}");
    }
    // Perspective: the silhouette of a sphere of radius r seen from distance D on the axis is
    // a circle of angular radius asin(r / D).
    let cam = cam.with_fov(35.0);
    let img = render(&pos, Some(&nrm), None, &cam, &o);
    let dist = (cam.eye - cam.target).length();
    let focal = 0.5 * size as f32 / (17.5f32.to_radians()).tan();
    let radius = focal * (1.0 / dist).asin().tan();
    let (inside, outside) = coverage(&img, radius, 1.1);
    assert!(inside > 0.95, "perspective inside {inside}");
    assert!(outside < 0.01, "perspective outside {outside}");
}

#[test]
fn lit_side_is_brighter() {
    let (pos, nrm) = sphere(20_000, 1.0, 2);
    let cam = Camera::frame(Vec3::splat(-1.0), Vec3::splat(1.0), -Vec3::Z, Vec3::Y);
    for edl in [false, true] {
        // Light from the right and the front (camera space).
        let o = RenderOptions {
            light_dir: Vec3::new(1.0, 0.0, 0.6),
            edl,
            ..opts(200)
        };
        let img = render(&pos, Some(&nrm), None, &cam, &o);
        let (right, nr) = mean_level(&img, |x, _| x >= 100);
        let (left, nl) = mean_level(&img, |x, _| x < 100);
        assert!(nr > 10_000 && nl > 10_000);
        assert!(right > left + 40.0, "edl {edl}: right {right} left {left}");
        // The light from the left makes it the other way round.
        let o = RenderOptions {
            light_dir: Vec3::new(-1.0, 0.0, 0.6),
            ..o
        };
        let img = render(&pos, Some(&nrm), None, &cam, &o);
        let (right, _) = mean_level(&img, |x, _| x >= 100);
        let (left, _) = mean_level(&img, |x, _| x < 100);
        assert!(left > right + 40.0, "edl {edl}: right {right} left {left}");
    }
}

#[test]
fn edl_darkens_the_far_side_of_an_occluding_contour() {
    // A small square sheet in front of a large one, no normals: flat shading everywhere, so
    // any darkening is the eye-dome lighting's.
    let mut pos = Vec::new();
    for i in 0..200 {
        for j in 0..200 {
            pos.push(Vec3::new(
                i as f32 / 100.0 - 1.0,
                j as f32 / 100.0 - 1.0,
                0.0,
            ));
        }
    }
    for i in 0..50 {
        for j in 0..50 {
            pos.push(Vec3::new(i as f32 / 100.0, j as f32 / 100.0, 0.5));
        }
    }
    let cam = Camera::frame(Vec3::new(-1.0, -1.0, 0.0), Vec3::ONE, -Vec3::Z, Vec3::Y);
    let o = RenderOptions {
        base_color: [200, 200, 200],
        ..opts(200)
    };
    let img = render(&pos, None, None, &cam, &o);
    let plain = render(&pos, None, None, &cam, &RenderOptions { edl: false, ..o });
    assert!(plain.rgb.iter().all(|&c| c == 200 || c == 0 || c == 255));
    // Far from any contour: untouched.
    assert_eq!(img.get(40, 150), Some([200, 200, 200]));
    // Just outside the near sheet's left edge (x = 0, the centre column 100): dark.
    let col = 100u32;
    let row = (100.0 - 100.0 / cam.ortho_height * 2.0 * 0.25) as u32;
    let darkest = (col.saturating_sub(3)..col)
        .map(|x| img.get(x, row).unwrap()[0])
        .min()
        .unwrap();
    assert!(darkest < 100, "{darkest}");
    // The near sheet itself is not darkened by the far one behind it.
    assert_eq!(img.get(col + 5, row), Some([200, 200, 200]));
}

#[test]
fn render_is_deterministic_across_thread_counts() {
    let (pos, nrm) = sphere(30_000, 1.0, 3);
    let colors: Vec<[u8; 3]> = pos
        .iter()
        .map(|p| [(p.x * 100.0 + 128.0) as u8, (p.y * 100.0 + 128.0) as u8, 90])
        .collect();
    let cam = Camera::frame(
        Vec3::splat(-1.0),
        Vec3::splat(1.0),
        Vec3::new(-1.0, -0.5, -1.0),
        Vec3::Y,
    )
    .with_fov(30.0);
    let o = opts(301);
    let run = || render(&pos, Some(&nrm), Some(&colors), &cam, &o).to_png_bytes();
    let a = run();
    assert_eq!(a, run());
    for threads in [1, 3] {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        assert!(pool.install(run) == a, "{threads} threads");
    }
}

#[test]
fn degenerate_input_does_not_panic() {
    let cam = Camera::frame(Vec3::splat(-1.0), Vec3::splat(1.0), -Vec3::Z, Vec3::Y);
    let o = opts(64);
    let empty = render(&[], None, None, &cam, &o);
    assert_eq!((empty.width, empty.height), (64, 64));
    assert!(empty.rgb.chunks(3).all(|c| c == BG));

    // NaN and infinite points, and points behind the camera, are skipped.
    let behind = cam.eye + (cam.eye - cam.target);
    let bad = [
        Vec3::NAN,
        Vec3::new(0.0, f32::NAN, 0.0),
        Vec3::new(f32::INFINITY, 0.0, 0.0),
        behind,
        cam.eye,
    ];
    for persp in [0.0, 40.0] {
        let c = cam.with_fov(persp);
        let img = render(&bad, Some(&[Vec3::NAN; 5][..]), None, &c, &o);
        assert!(img.rgb.chunks(3).all(|c| c == BG), "fov {persp}");
        // Mixed with one good point (short normal and colour slices): that one is drawn.
        let mut pts = bad.to_vec();
        pts.push(Vec3::ZERO);
        let img = render(&pts, Some(&[Vec3::X][..]), Some(&[[1, 2, 3]][..]), &c, &o);
        assert_ne!(img.get(32, 32), Some(BG), "fov {persp}");
    }
    // Zero-size pictures, a degenerate camera and huge fixed point sizes.
    let (pos, nrm) = sphere(1000, 1.0, 4);
    let img = render(
        &pos,
        Some(&nrm),
        None,
        &cam,
        &RenderOptions { width: 0, ..o },
    );
    assert!(img.rgb.is_empty());
    let odd = Camera {
        eye: Vec3::ZERO,
        target: Vec3::ZERO,
        up: Vec3::ZERO,
        fov_y_deg: f32::NAN,
        ortho_height: -1.0,
    };
    render(&pos, Some(&nrm), None, &odd, &o);
    let huge = RenderOptions {
        point_size_px: 1e9,
        ..o
    };
    render(&pos, Some(&nrm), None, &cam.with_fov(60.0), &huge);
    // Every point in one spot.
    let same = vec![Vec3::ONE; 100];
    let img = render(
        &same,
        None,
        None,
        &Camera::frame(Vec3::ZERO, Vec3::ONE, -Vec3::Z, Vec3::Y),
        &o,
    );
    assert!(img.rgb.chunks(3).any(|c| c != BG));
}

// ------------------------------------------------------------------------------------------
// Overlays
// ------------------------------------------------------------------------------------------

#[test]
fn overlays_draw_segments_and_circles() {
    let cam = Camera::frame(Vec3::splat(-1.0), Vec3::splat(1.0), -Vec3::Z, Vec3::Y);
    let mut img = Image::new(100, 100, BG);
    let red = [255, 0, 0];
    overlay_segments(
        &mut img,
        &cam,
        &[(Vec3::new(-0.5, 0.0, 0.0), Vec3::new(0.5, 0.0, 0.0))],
        red,
        3.0,
    );
    // A horizontal line through the centre, 3 px wide, from x ≈ 27 to x ≈ 73.
    let ppu = 100.0 / cam.ortho_height;
    let (x0, x1) = ((50.0 - 0.5 * ppu) as u32, (50.0 + 0.5 * ppu) as u32);
    for x in x0 + 1..x1 {
        assert_eq!(img.get(x, 50), Some(red), "x {x}");
        assert_eq!(img.get(x, 49), Some(red), "x {x}");
        assert_eq!(img.get(x, 46), Some(BG), "x {x}");
    }
    assert_eq!(img.get(x0 - 3, 50), Some(BG));
    assert_eq!(img.get(x1 + 3, 50), Some(BG));

    let mut img = Image::new(100, 100, BG);
    overlay_spheres(&mut img, &cam, &[(Vec3::ZERO, 0.5)], red);
    let r = 0.5 * ppu;
    let on = |x: f32, y: f32| img.get(x as u32, y as u32).unwrap();
    assert_eq!(on(50.0, 50.0), BG, "centre");
    // On the circle, at the four compass points, the pixel is (mostly) red.
    for (x, y) in [
        (50.0 + r, 50.0),
        (50.0 - r, 50.0),
        (50.0, 50.0 + r),
        (50.0, 50.0 - r),
    ] {
        let c = on(x, y);
        assert!(c[0] > 128 && c[2] < 128, "{x} {y}: {c:?}");
    }
    assert_eq!(on(50.0 + r + 4.0, 50.0), BG);
    assert_eq!(on(50.0 + r - 4.0, 50.0), BG);

    // Segments behind the camera, with NaN ends, and crossing the eye: no panic.
    let mut img = Image::new(50, 50, BG);
    let back = cam.eye + (cam.eye - cam.target);
    overlay_segments(
        &mut img,
        &cam.with_fov(50.0),
        &[
            (back, back + Vec3::X),
            (Vec3::NAN, Vec3::ZERO),
            (back, Vec3::ZERO),
        ],
        red,
        2.0,
    );
    overlay_spheres(
        &mut img,
        &cam,
        &[(Vec3::NAN, 1.0), (Vec3::ZERO, f32::INFINITY)],
        red,
    );
}

// ------------------------------------------------------------------------------------------
// A bundled statue
// ------------------------------------------------------------------------------------------

#[test]
fn dancing_girl_renders_upright_from_the_front() {
    let cloud = read_ply(statues_dir().join("statue_dancing_girl_thorvaldsen.ply")).unwrap();
    let bbox = cloud.bounding_box().unwrap();
    let (w, h) = (480u32, 800u32);
    let cam = Camera::front(bbox.min, bbox.max, w as f32 / h as f32);
    let o = RenderOptions {
        width: w,
        height: h,
        background: BG,
        ..RenderOptions::default()
    };
    let img = render(&cloud.positions, cloud.normals.as_deref(), None, &cam, &o);
    // The statue (0.81 wide, 1.80 tall in the file's +Y-up frame) stands upright: its
    // covered pixels span about 1.8 / 1.08 of the picture's height and ~2.2 times less in
    // width.
    let (mut x0, mut x1, mut y0, mut y1, mut n) = (u32::MAX, 0, u32::MAX, 0, 0usize);
    for y in 0..h {
        for x in 0..w {
            if img.get(x, y).unwrap() != BG {
                (x0, x1, y0, y1) = (x0.min(x), x1.max(x), y0.min(y), y1.max(y));
                n += 1;
            }
        }
    }
    let (bw, bh) = ((x1 - x0 + 1) as f32, (y1 - y0 + 1) as f32);
    assert!(bh > 0.88 * h as f32 && bh < 0.95 * h as f32, "height {bh}");
    assert!(bh / bw > 1.9 && bh / bw < 2.6, "aspect {}", bh / bw);
    let fill = n as f32 / (bw * bh);
    assert!(fill > 0.3 && fill < 0.8, "fill {fill}");
    img.save_png(scratch("render_statue").join("dancing_girl_front.png"))
        .unwrap();
}

#[test]
fn hole_filling_closes_gaps_between_splats() {
    // A randomly sampled near square (red) over a dense far square (green), splats too small
    // to close the near one: the far colour shows through its holes unless they are filled.
    let mut rng = Rng::new(5);
    let mut pos = Vec::new();
    let mut col = Vec::new();
    for _ in 0..6000 {
        pos.push(Vec3::new(rng.range(-0.5, 0.5), rng.range(-0.5, 0.5), 0.5));
        col.push([255, 0, 0]);
    }
    for i in 0..300 {
        for j in 0..300 {
            pos.push(Vec3::new(
                i as f32 / 150.0 - 1.0,
                j as f32 / 150.0 - 1.0,
                0.0,
            ));
            col.push([0, 255, 0]);
        }
    }
    let cam = Camera::frame(Vec3::new(-1.0, -1.0, 0.0), Vec3::ONE, -Vec3::Z, Vec3::Y);
    let o = RenderOptions {
        point_size_px: 2.0,
        edl: false,
        ..opts(200)
    };
    let green_inside = |img: &Image| {
        let half = (0.45 * 200.0 / cam.ortho_height) as u32;
        let mut n = 0;
        for y in 100 - half..100 + half {
            for x in 100 - half..100 + half {
                n += (img.get(x, y).unwrap()[1] > 128) as usize;
            }
        }
        n as f64 / (4 * half * half) as f64
    };
    let open = green_inside(&render(
        &pos,
        None,
        Some(&col),
        &cam,
        &RenderOptions {
            fill_holes: false,
            ..o
        },
    ));
    let filled = green_inside(&render(&pos, None, Some(&col), &cam, &o));
    assert!(open > 0.03, "holes without filling: {open}");
    assert!(filled < 0.2 * open, "filled {filled}, open {open}");
}

// ------------------------------------------------------------------------------------------
// Pose pictograms
// ------------------------------------------------------------------------------------------

mod pictograms {
    use pygmalion::anatomy::{Pose, Skeleton, Template};
    use pygmalion::math::{Quat, Vec3};
    use pygmalion::render::Image;
    use pygmalion::render::pictogram::{
        Pictogram, PictogramOptions, pictogram, pose_pictogram, standing_height,
    };
    use std::sync::Arc;

    use crate::common::scratch;

    /// The built-in poses of `config/poses/` (every built-in name but `identity`).
    fn poses() -> Vec<&'static str> {
        Pose::builtin_names()
            .iter()
            .copied()
            .filter(|n| *n != "identity")
            .collect()
    }

    fn human() -> Arc<Template> {
        Arc::new(Template::builtin("human").unwrap())
    }

    /// The pictogram of a built-in pose and the skeleton it shows.
    fn draw(name: &str, o: &PictogramOptions) -> (Pictogram, Skeleton) {
        let pose = Pose::builtin(name).unwrap();
        let skel = pose
            .apply(&Skeleton::rest(human()), &Pose::source_path(name))
            .unwrap();
        (pose_pictogram(&pose, human(), o).unwrap(), skel)
    }

    /// Pixels at least half covered.
    fn ink(p: &Pictogram) -> usize {
        p.rgba.chunks_exact(4).filter(|c| c[3] >= 128).count()
    }

    /// Pixels whose coverage differs by more than a quarter.
    fn differing(a: &Pictogram, b: &Pictogram) -> usize {
        a.rgba
            .chunks_exact(4)
            .zip(b.rgba.chunks_exact(4))
            .filter(|(x, y)| x[3].abs_diff(y[3]) > 64)
            .count()
    }

    /// The pixel row of the top of the head (the head bone's far sphere).
    fn head_top_row(p: &Pictogram, s: &Skeleton) -> f32 {
        let head = s.template.bone_index("head").unwrap();
        let b = s.pose().bones[head];
        let top = s.root_rotation.inverse() * (b.c2 - s.root_position);
        p.frame.to_pixel(top).y - b.r2 * 0.8 * p.frame.scale
    }

    #[test]
    fn every_built_in_pose_gets_a_distinct_pictogram() {
        let o = PictogramOptions::default();
        let start = std::time::Instant::now();
        let names = poses();
        assert!(names.len() >= 7, "the built-in poses: {names:?}");
        let all: Vec<(Pictogram, Skeleton)> = names.iter().map(|n| draw(n, &o)).collect();
        println!(
            "{} pictograms in {:.1} ms",
            all.len(),
            start.elapsed().as_secs_f64() * 1e3
        );
        // A strip of them, for people to look at.
        let strip: Vec<Image> = all.iter().map(|(p, _)| p.to_image([51, 56, 71])).collect();
        Image::hstack(&strip, 4, [0, 0, 0])
            .save_png(scratch("render_pictograms").join("poses.png"))
            .unwrap();
        let n = (o.width * o.height) as usize;
        for (name, (p, _)) in names.iter().zip(&all) {
            let (x0, y0, x1, y1) = p.ink_bounds(128).expect("not empty");
            println!(
                "{name}: {} pixels of ink, {}x{} pixels",
                ink(p),
                x1 - x0 + 1,
                y1 - y0 + 1
            );
            assert_eq!((p.width, p.height, p.rgba.len()), (64, 64, n * 4));
            // A figure, not a blob or a speck: 5–30% of the picture, inside the margins,
            // standing on the bottom margin; a transparent background and antialiased edges.
            assert!(
                ink(p) * 20 > n && ink(p) * 10 < 3 * n,
                "{name}: ink {}",
                ink(p)
            );
            assert!(
                x0 >= 2 && y0 >= 2 && x1 <= 61 && y1 <= 61,
                "{name}: {x0},{y0}–{x1},{y1}"
            );
            assert!(
                y1 >= 60,
                "{name} does not stand on the ground (lowest row {y1})"
            );
            assert_eq!(p.alpha(0, 0), 0);
            let partial = p.rgba.chunks_exact(4).filter(|c| c[3] > 0 && c[3] < 255);
            assert!(partial.count() > 20, "{name}: no antialiasing");
        }
        // Different poses, different pictures (the closest pair, greeting and rest, differs in
        // about a hundred pixels).
        let mut closest = (usize::MAX, "", "");
        for i in 0..all.len() {
            for j in 0..i {
                let d = differing(&all[i].0, &all[j].0);
                closest = closest.min((d, names[i], names[j]));
            }
        }
        println!(
            "closest pair: {} and {}, {} pixels differ",
            closest.1, closest.2, closest.0
        );
        assert!(closest.0 >= 15, "{closest:?}");
    }

    #[test]
    fn pictograms_measure_the_pose() {
        let o = PictogramOptions::default();
        let (rest, rest_s) = draw("rest", &o);
        let (raised, raised_s) = draw("arms_raised", &o);
        let (seated, _) = draw("seated", &o);
        let (thinker, _) = draw("thinker", &o);
        // One scale for every pose of a skeleton.
        assert_eq!(rest.frame.scale, raised.frame.scale);
        assert_eq!(rest.frame.scale, seated.frame.scale);
        // Standing, nothing rises above the head; arms raised, the hands do.
        let above = |p: &Pictogram, row: f32| {
            (0..p.height)
                .filter(|&y| (y as f32) < row - 1.0)
                .flat_map(|y| (0..p.width).map(move |x| (x, y)))
                .filter(|&(x, y)| p.alpha(x, y) >= 128)
                .count()
        };
        let rest_above = above(&rest, head_top_row(&rest, &rest_s));
        let raised_above = above(&raised, head_top_row(&raised, &raised_s));
        println!("ink above the head: rest {rest_above}, arms raised {raised_above} pixels");
        assert_eq!(rest_above, 0);
        assert!(raised_above >= 30, "{raised_above} pixels above the head");
        // Seated (and the Thinker, bent forward) is shorter than standing.
        let height = |p: &Pictogram| {
            let (_, y0, _, y1) = p.ink_bounds(128).unwrap();
            (y1 - y0 + 1) as f32
        };
        println!(
            "heights: rest {}, arms raised {}, seated {}, thinker {} pixels",
            height(&rest),
            height(&raised),
            height(&seated),
            height(&thinker)
        );
        assert!(height(&seated) < 0.85 * height(&rest));
        assert!(height(&thinker) < height(&seated));
        assert!(height(&raised) > 1.15 * height(&rest));
        // The standing figure is 1 / frame_heights of the usable height (60 pixels).
        let want = 60.0 / o.frame_heights;
        assert!(
            (height(&rest) - want).abs() <= 2.0,
            "rest {} vs {want}",
            height(&rest)
        );
    }

    #[test]
    fn pictogram_ignores_where_the_statue_stands_and_its_size() {
        // A skeleton placed, turned and scaled like a fitted scan draws like the template's.
        let o = PictogramOptions::default();
        let pose = Pose::builtin("walking").unwrap();
        let src = Pose::source_path("walking");
        let placed = Skeleton::rest_placed(
            human(),
            Vec3::new(3.0, -1.0, 2.0),
            Quat::from_rotation_y(2.0) * Quat::from_rotation_x(0.4),
            170.0,
        );
        let a = pictogram(&pose.apply(&placed, &src).unwrap(), &o);
        let (b, _) = draw("walking", &o);
        assert!(
            (standing_height(&placed) / standing_height(&Skeleton::rest(human())) - 170.0).abs()
                < 0.01
        );
        assert!(
            differing(&a, &b) <= 2,
            "{} pixels differ",
            differing(&a, &b)
        );
        // The view turns the figure: from the front and from the side differ.
        let side = PictogramOptions {
            yaw_deg: -90.0,
            ..o
        };
        let front = PictogramOptions { yaw_deg: 0.0, ..o };
        let (s, _) = draw("walking", &side);
        let (f, _) = draw("walking", &front);
        assert!(differing(&s, &f) > 40);
        // Seen from the side the stride shows: the feet (the lowest eighth of the figure) lie
        // farther apart than seen from the front.
        let feet = |p: &Pictogram| {
            let (_, y0, _, y1) = p.ink_bounds(128).unwrap();
            let from = y1 - (y1 - y0) / 8;
            let xs: Vec<u32> = (from..=y1)
                .flat_map(|y| (0..p.width).map(move |x| (x, y)))
                .filter(|&(x, y)| p.alpha(x, y) >= 128)
                .map(|(x, _)| x)
                .collect();
            xs.iter().max().unwrap() - xs.iter().min().unwrap() + 1
        };
        println!(
            "walking: feet {} pixels apart from the side, {} from the front",
            feet(&s),
            feet(&f)
        );
        assert!(feet(&s) > feet(&f) + 4);
    }

    #[test]
    fn a_pose_that_does_not_fit_the_template_is_refused() {
        let mut pose = Pose::builtin("arms_raised").unwrap();
        pose.bones.insert("l_wing".into(), Default::default());
        let err = pose_pictogram(&pose, human(), &PictogramOptions::default()).unwrap_err();
        assert!(err.to_string().contains("l_wing"), "{err}");
        // A pose of another template's bones.
        let quadruped = Arc::new(Template::builtin("quadruped").unwrap());
        let err = pose_pictogram(
            &Pose::builtin("thinker").unwrap(),
            quadruped,
            &PictogramOptions::default(),
        );
        assert!(err.is_err());
        // Degenerate sizes do not panic.
        let tiny = PictogramOptions {
            width: 1,
            height: 1,
            margin_px: 5.0,
            ..PictogramOptions::default()
        };
        let (p, _) = draw("rest", &tiny);
        assert_eq!(p.rgba.len(), 4);
    }
}
