//! Tests of `pygmalion::cloud::ply`: round trips, the three formats with extra properties and
//! elements, an error corpus of malformed files, robustness against damaged bytes, and the
//! bundled (and, in the extended run, the shared) real scans.

use std::path::{Path, PathBuf};

use pygmalion::cloud::PointCloud;
use pygmalion::cloud::ply::{
    PlyError, PlyProblem, ReadOptions, WriteOptions, read_ply, read_ply_bytes, read_ply_with,
    read_ply_with_property, write_ply, write_ply_to,
};
use pygmalion::math::Vec3;

use crate::common::{scratch, shared_plys, statues_dir};

// ------------------------------------------------------------------------------------------
// Helpers
// ------------------------------------------------------------------------------------------

/// A deterministic pseudo-random sequence in [0, 1).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        ((self.0 >> 40) as f32) / (1u64 << 24) as f32
    }
    fn vec(&mut self) -> Vec3 {
        Vec3::new(
            self.next() * 2.0 - 1.0,
            self.next() * 2.0 - 1.0,
            self.next() * 2.0 - 1.0,
        )
    }
}

fn random_cloud(n: usize, normals: bool, colors: bool) -> PointCloud {
    let mut rng = Lcg(7);
    let positions: Vec<Vec3> = (0..n).map(|_| rng.vec() * 1.7).collect();
    let normals = normals.then(|| {
        (0..n)
            .map(|_| (rng.vec() + Vec3::new(0.0, 0.0, 0.01)).normalize_or(Vec3::Z))
            .collect()
    });
    let colors = colors.then(|| {
        (0..n)
            .map(|i| [(i % 256) as u8, (i * 7 % 256) as u8, (255 - i % 256) as u8])
            .collect()
    });
    PointCloud {
        positions,
        normals,
        colors,
    }
}

fn bits(v: &[Vec3]) -> Vec<[u32; 3]> {
    v.iter()
        .map(|p| [p.x.to_bits(), p.y.to_bits(), p.z.to_bits()])
        .collect()
}

/// Little/big-endian byte builder for hand-made binary bodies.
struct Bytes {
    data: Vec<u8>,
    big: bool,
}
impl Bytes {
    fn new(header: &str, big: bool) -> Self {
        Bytes {
            data: header.as_bytes().to_vec(),
            big,
        }
    }
    fn f32(&mut self, v: f32) -> &mut Self {
        let b = if self.big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.data.extend_from_slice(&b);
        self
    }
    fn f64(&mut self, v: f64) -> &mut Self {
        let b = if self.big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.data.extend_from_slice(&b);
        self
    }
    fn i32(&mut self, v: i32) -> &mut Self {
        let b = if self.big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.data.extend_from_slice(&b);
        self
    }
    fn u32(&mut self, v: u32) -> &mut Self {
        let b = if self.big {
            v.to_be_bytes()
        } else {
            v.to_le_bytes()
        };
        self.data.extend_from_slice(&b);
        self
    }
    fn u8(&mut self, v: u8) -> &mut Self {
        self.data.push(v);
        self
    }
    fn i8(&mut self, v: i8) -> &mut Self {
        self.data.push(v as u8);
        self
    }
    fn f32s(&mut self, vs: &[f32]) -> &mut Self {
        for &v in vs {
            self.f32(v);
        }
        self
    }
    fn take(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.data)
    }
}

fn write_file(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write test file");
    path
}

fn header_xyz(format: &str, n: usize) -> String {
    format!(
        "ply\nformat {format} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n\
         property float z\nend_header\n"
    )
}

// ------------------------------------------------------------------------------------------
// Round trips
// ------------------------------------------------------------------------------------------

#[test]
fn round_trip_with_normals_is_bit_exact() {
    let dir = scratch("cloud_ply_round_normals");
    let cloud = random_cloud(5000, true, false);
    let path = dir.join("normals.ply");
    write_ply(&path, &cloud, &WriteOptions::default()).unwrap();
    let back = read_ply(&path).unwrap();
    assert_eq!(back.len(), 5000);
    assert_eq!(bits(&back.positions), bits(&cloud.positions));
    assert_eq!(
        bits(back.normals.as_ref().unwrap()),
        bits(cloud.normals.as_ref().unwrap())
    );
    assert!(back.colors.is_none());
    // Same bytes through write_ply_to.
    let mut bytes = Vec::new();
    write_ply_to(&mut bytes, &cloud, &WriteOptions::default()).unwrap();
    assert_eq!(bytes, std::fs::read(&path).unwrap());
    let from_bytes = read_ply_bytes(Path::new("mem.ply"), &bytes, &ReadOptions::default()).unwrap();
    assert_eq!(from_bytes, back);
}

#[test]
fn round_trip_positions_only_and_colours() {
    let dir = scratch("cloud_ply_round_colours");
    let plain = random_cloud(300, false, false);
    write_ply(dir.join("plain.ply"), &plain, &WriteOptions::default()).unwrap();
    let back = read_ply(dir.join("plain.ply")).unwrap();
    assert_eq!(bits(&back.positions), bits(&plain.positions));
    assert!(back.normals.is_none() && back.colors.is_none());

    let coloured = random_cloud(300, true, true);
    write_ply(dir.join("colours.ply"), &coloured, &WriteOptions::default()).unwrap();
    let back = read_ply(dir.join("colours.ply")).unwrap();
    assert_eq!(back, coloured);
    assert_eq!(bits(&back.positions), bits(&coloured.positions));

    let opts = WriteOptions {
        colors: false,
        ..WriteOptions::default()
    };
    write_ply(dir.join("no_colours.ply"), &coloured, &opts).unwrap();
    let back = read_ply(dir.join("no_colours.ply")).unwrap();
    assert!(back.colors.is_none());
    assert_eq!(
        bits(back.normals.as_ref().unwrap()),
        bits(coloured.normals.as_ref().unwrap())
    );
}

#[test]
fn round_trip_with_labels() {
    let dir = scratch("cloud_ply_round_labels");
    let cloud = random_cloud(1000, true, true);
    // Every 100th point has no label (`u32::MAX`, written as -1).
    let labels: Vec<u32> = (0..1000)
        .map(|i| {
            if i % 100 == 7 {
                u32::MAX
            } else {
                (i * 13 % 17) as u32
            }
        })
        .collect();
    let opts = WriteOptions {
        colors: true,
        labels: Some(("bone".into(), labels.clone())),
    };
    let path = dir.join("labels.ply");
    write_ply(&path, &cloud, &opts).unwrap();
    let text = std::fs::read(&path).unwrap();
    assert!(String::from_utf8_lossy(&text[..300]).contains("property int bone\n"));
    let back = read_ply(&path).unwrap();
    assert_eq!(back, cloud);
    assert_eq!(bits(&back.positions), bits(&cloud.positions));
    assert_eq!(
        bits(back.normals.as_ref().unwrap()),
        bits(cloud.normals.as_ref().unwrap())
    );
    let (again, values) = read_ply_with_property(&path, &ReadOptions::default(), "bone").unwrap();
    assert_eq!(again, cloud);
    assert_eq!(values.iter().filter(|&&v| v == -1.0).count(), 10);
    let values: Vec<u32> = values
        .iter()
        .map(|&v| if v < 0.0 { u32::MAX } else { v as u32 })
        .collect();
    assert_eq!(values, labels);
    // A property that is not there.
    let e = read_ply_with_property(&path, &ReadOptions::default(), "muscle").unwrap_err();
    assert!(
        matches!(&e.problem, PlyProblem::MissingProperty(n) if n == "muscle"),
        "{e}"
    );
    assert!(e.to_string().contains("labels.ply"));
}

#[test]
fn failed_write_keeps_the_old_file_and_leaves_no_temporary() {
    let dir = scratch("cloud_ply_write_fail");
    let path = dir.join("good.ply");
    let good = random_cloud(50, true, false);
    write_ply(&path, &good, &WriteOptions::default()).unwrap();
    let before = std::fs::read(&path).unwrap();

    let mut bad = random_cloud(60, true, false);
    bad.normals.as_mut().unwrap().pop();
    let e = write_ply(&path, &bad, &WriteOptions::default()).unwrap_err();
    assert!(matches!(e.problem, PlyProblem::Inconsistent(_)), "{e}");
    assert!(e.to_string().contains("good.ply"), "{e}");

    let labels = Some(("bone".to_string(), vec![1u32; 3]));
    let e = write_ply(
        &path,
        &good,
        &WriteOptions {
            colors: true,
            labels,
        },
    )
    .unwrap_err();
    assert!(matches!(e.problem, PlyProblem::Inconsistent(_)), "{e}");
    let labels = Some(("x".to_string(), vec![1u32; 50]));
    let e = write_ply(
        &path,
        &good,
        &WriteOptions {
            colors: true,
            labels,
        },
    )
    .unwrap_err();
    assert!(matches!(e.problem, PlyProblem::Inconsistent(_)), "{e}");
    let labels = Some(("bone".to_string(), vec![i32::MAX as u32 + 1; 50]));
    let e = write_ply(
        &path,
        &good,
        &WriteOptions {
            colors: true,
            labels,
        },
    )
    .unwrap_err();
    assert!(matches!(e.problem, PlyProblem::Inconsistent(_)), "{e}");

    assert_eq!(std::fs::read(&path).unwrap(), before);
    let names: Vec<_> = std::fs::read_dir(&dir)
        .unwrap()
        .map(|e| e.unwrap().file_name())
        .collect();
    assert_eq!(names.len(), 1, "{names:?}");

    // Unwritable places.
    let e = write_ply(
        dir.join("no/such/dir/a.ply"),
        &good,
        &WriteOptions::default(),
    )
    .unwrap_err();
    assert!(matches!(e.problem, PlyProblem::Write(_)), "{e}");
    assert!(e.to_string().contains("a.ply"), "{e}");
    let e = write_ply(&dir, &good, &WriteOptions::default()).unwrap_err();
    assert!(matches!(e.problem, PlyProblem::IsDirectory), "{e}");

    // Overwriting a good file with another good one.
    let small = good.select(&[3, 1, 4]);
    write_ply(&path, &small, &WriteOptions::default()).unwrap();
    assert_eq!(read_ply(&path).unwrap(), small);
}

// ------------------------------------------------------------------------------------------
// Formats, extra properties and elements
// ------------------------------------------------------------------------------------------

#[test]
fn reads_ascii_with_doubles_extra_properties_and_faces_around_the_vertices() {
    let dir = scratch("cloud_ply_ascii");
    let text = "ply\r\nformat ascii 1.0\r\ncomment made by hand\r\nobj_info test\r\n\
        element face 2\r\nproperty list uchar int vertex_indices\r\n\
        element vertex 3\r\nproperty double x\r\nproperty double y\r\nproperty double z\r\n\
        property float confidence\r\nproperty uchar intensity\r\n\
        property float nx\r\nproperty float ny\r\nproperty float nz\r\n\
        property uchar red\r\nproperty uchar green\r\nproperty uchar blue\r\n\
        element edge 1\r\nproperty int vertex1\r\nproperty int vertex2\r\nend_header\r\n\
        3 0 1 2\r\n4 0 1 2 0\r\n\
        0.5 -1.25 2e3 0.9 17 0 0 2 255 0 10\r\n\
        1 2 3 0.1 3 0 1 0 0 128 255\r\n\
        -0.000001 1e-3 4.5 1 1 0.6 0.8 0 1 2 3\r\n\
        0 1\r\n";
    let path = write_file(&dir, "mixed.ply", text.as_bytes());
    let cloud = read_ply(&path).unwrap();
    assert_eq!(
        cloud.positions,
        vec![
            Vec3::new(0.5, -1.25, 2000.0),
            Vec3::new(1.0, 2.0, 3.0),
            Vec3::new(-0.000001f64 as f32, 1e-3f64 as f32, 4.5)
        ]
    );
    // The first normal (0, 0, 2) is rescaled to unit length.
    assert_eq!(
        cloud.normals.unwrap(),
        vec![Vec3::Z, Vec3::Y, Vec3::new(0.6, 0.8, 0.0)]
    );
    assert_eq!(
        cloud.colors.unwrap(),
        vec![[255, 0, 10], [0, 128, 255], [1, 2, 3]]
    );
    let (_, confidence) =
        read_ply_with_property(&path, &ReadOptions::default(), "confidence").unwrap();
    assert_eq!(confidence, vec![0.9, 0.1, 1.0]);
}

/// A binary file: a face element (list property) before the vertices, doubles, extras, and an
/// edge element after them.
fn binary_mesh(big: bool) -> Vec<u8> {
    let format = if big {
        "binary_big_endian"
    } else {
        "binary_little_endian"
    };
    let header = format!(
        "ply\nformat {format} 1.0\ncomment mesh\nelement face 2\n\
         property list uchar int vertex_indices\nproperty uchar flags\n\
         element vertex 3\nproperty double x\nproperty double y\nproperty double z\n\
         property float confidence\nproperty float intensity\nproperty list uchar float tex\n\
         property float red\nproperty float green\nproperty float blue\n\
         element edge 2\nproperty int a\nproperty int b\nend_header\n"
    );
    let mut b = Bytes::new(&header, big);
    // faces
    b.u8(3).i32(0).i32(1).i32(2).u8(7);
    b.u8(4).i32(0).i32(1).i32(2).i32(0).u8(9);
    // vertices
    let rows: [[f64; 3]; 3] = [[0.5, -1.25, 2e3], [1.0, 2.0, 3.0], [1e-6, 1e-3, 4.5]];
    for (i, r) in rows.iter().enumerate() {
        b.f64(r[0]).f64(r[1]).f64(r[2]).f32(0.5).f32(i as f32);
        b.u8(i as u8);
        for k in 0..i {
            b.f32(k as f32);
        }
        b.f32(1.0).f32(0.5).f32(0.0);
    }
    // edges
    b.i32(0).i32(1).i32(1).i32(2);
    b.take()
}

#[test]
fn reads_binary_little_and_big_endian_meshes() {
    let dir = scratch("cloud_ply_binary");
    for big in [false, true] {
        let path = write_file(&dir, &format!("mesh_{big}.ply"), &binary_mesh(big));
        let cloud = read_ply(&path).unwrap();
        assert_eq!(
            cloud.positions,
            vec![
                Vec3::new(0.5, -1.25, 2000.0),
                Vec3::new(1.0, 2.0, 3.0),
                Vec3::new(1e-6f64 as f32, 1e-3f64 as f32, 4.5)
            ],
            "big endian: {big}"
        );
        assert!(cloud.normals.is_none());
        assert_eq!(cloud.colors.unwrap(), vec![[255, 128, 0]; 3]);
        let (_, intensity) =
            read_ply_with_property(&path, &ReadOptions::default(), "intensity").unwrap();
        assert_eq!(intensity, vec![0.0, 1.0, 2.0]);
    }
}

#[test]
fn reads_plain_binary_both_endians_and_int_coordinates() {
    let dir = scratch("cloud_ply_binary_plain");
    for (big, format) in [(false, "binary_little_endian"), (true, "binary_big_endian")] {
        let mut b = Bytes::new(&header_xyz(format, 2), big);
        b.f32s(&[1.0, 2.0, 3.0, -4.0, 5.5, 6.25]);
        let cloud = read_ply(write_file(&dir, &format!("{format}.ply"), &b.take())).unwrap();
        assert_eq!(
            cloud.positions,
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::new(-4.0, 5.5, 6.25)]
        );
    }
    let header = "ply\nformat binary_little_endian 1.0\nelement vertex 2\nproperty short x\n\
                  property int y\nproperty uchar z\nend_header\n";
    let mut b = Bytes::new(header, false);
    b.data.extend_from_slice(&(-3i16).to_le_bytes());
    b.i32(100000).u8(200);
    b.data.extend_from_slice(&7i16.to_le_bytes());
    b.i32(-1).u8(0);
    let cloud = read_ply(write_file(&dir, "ints.ply", &b.take())).unwrap();
    assert_eq!(
        cloud.positions,
        vec![Vec3::new(-3.0, 100000.0, 200.0), Vec3::new(7.0, -1.0, 0.0)]
    );
}

#[test]
fn ascii_mesh_gives_its_vertices() {
    let dir = scratch("cloud_ply_ascii_mesh");
    let text = "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\n\
                property float z\nelement face 2\nproperty list uchar int vertex_indices\n\
                end_header\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2\n3 0 2 3\n";
    let cloud = read_ply(write_file(&dir, "tetra.ply", text.as_bytes())).unwrap();
    assert_eq!(cloud.len(), 4);
    assert_eq!(cloud.positions[3], Vec3::Z);
    // Damaged face data after the vertices does not matter.
    let text = text.replace("3 0 2 3\n", "x");
    assert_eq!(
        read_ply(write_file(&dir, "tetra2.ply", text.as_bytes())).unwrap(),
        cloud
    );
}

/// Header lines ply-rs parses: comments and obj_info anywhere (also non-UTF-8 ones), CRLF,
/// blank lines, stray spaces and tabs, and the integer type aliases.
#[test]
fn header_with_comments_blank_lines_and_type_aliases() {
    let mut bytes = b"ply\r\nformat binary_little_endian 1.0 \r\ncomment caf\xe9 \xff\r\n".to_vec();
    bytes.extend_from_slice(
        b"\r\n  obj_info scanner 3\r\ncomment\r\nelement vertex 2\r\n\
          property float32 x\r\nproperty\tfloat64  y\r\ncomment between properties\r\n\
          property int16 z\r\nproperty uint8 intensity\r\n   \r\nend_header\r\n",
    );
    for (x, y, z, i) in [(1.5f32, -2.0f64, 7i16, 9u8), (0.25, 1e10, -3, 200)] {
        bytes.extend_from_slice(&x.to_le_bytes());
        bytes.extend_from_slice(&y.to_le_bytes());
        bytes.extend_from_slice(&z.to_le_bytes());
        bytes.push(i);
    }
    let name = Path::new("comments.ply");
    let cloud = read_ply_bytes(name, &bytes, &ReadOptions::default()).unwrap();
    assert_eq!(
        cloud.positions,
        vec![Vec3::new(1.5, -2.0, 7.0), Vec3::new(0.25, 1e10, -3.0)]
    );
    // Ascii line numbers still count the blank header lines.
    let text = "ply\nformat ascii 1.0\n\ncomment x\n\nelement vertex 2\nproperty float x\n\
                property float y\nproperty float z\nend_header\n0 0 0\n1 q 1\n";
    let e = read_ply_bytes(name, text.as_bytes(), &ReadOptions::default()).unwrap_err();
    assert!(
        matches!(e.problem, PlyProblem::BadValue { line: 12, .. }),
        "{e}"
    );
    // A rejected header line names its line and carries ply-rs's reason.
    let text = "ply\nformat ascii 1.0\n\nelement vertex 1\nproperty float x y\nend_header\n";
    let e = read_ply_bytes(name, text.as_bytes(), &ReadOptions::default()).unwrap_err();
    let message = e.to_string();
    assert!(
        message.contains("line 5: garbled property line"),
        "{message}"
    );
    assert!(message.contains("ply-rs"), "{message}");
}

/// Files written entirely by ply-rs (header and payload, through its `DefaultElement`) read
/// back through our reader, in the three formats, with a face element before the vertices.
#[test]
fn reads_files_written_by_ply_rs() {
    use ply_rs::ply::{
        Addable, DefaultElement, ElementDef, Encoding, Ply, Property, PropertyDef, PropertyType,
        ScalarType,
    };
    let points = [
        [0.5f32, -1.25, 3.0],
        [1e-3, 2.0, -7.5],
        [f32::MAX, f32::MIN_POSITIVE, 0.0],
    ];
    for encoding in [
        Encoding::Ascii,
        Encoding::BinaryLittleEndian,
        Encoding::BinaryBigEndian,
    ] {
        let mut ply = Ply::<DefaultElement>::new();
        ply.header.encoding = encoding;
        ply.header.comments.push("from ply-rs".into());
        ply.header.obj_infos.push("cross-check".into());
        let mut face = ElementDef::new("face".into());
        face.properties.add(PropertyDef::new(
            "vertex_indices".into(),
            PropertyType::List(ScalarType::UChar, ScalarType::Int),
        ));
        ply.header.elements.add(face);
        let mut vertex = ElementDef::new("vertex".into());
        for name in ["x", "y", "z", "red", "green", "blue"] {
            let ty = if name.len() == 1 {
                ScalarType::Float
            } else {
                ScalarType::UChar
            };
            vertex
                .properties
                .add(PropertyDef::new(name.into(), PropertyType::Scalar(ty)));
        }
        ply.header.elements.add(vertex);
        // Three faces of three indices: ply-rs 0.1.3's binary writer writes the element
        // count as the length of every list, so only lists that long come out right.
        let faces = (0..3)
            .map(|i| {
                let mut f = DefaultElement::new();
                f.insert("vertex_indices".into(), Property::ListInt(vec![i, 1, 2]));
                f
            })
            .collect();
        ply.payload.insert("face".into(), faces);
        let vertices = points
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let mut v = DefaultElement::new();
                for (k, name) in ["x", "y", "z"].into_iter().enumerate() {
                    v.insert(name.into(), Property::Float(p[k]));
                }
                for (k, name) in ["red", "green", "blue"].into_iter().enumerate() {
                    v.insert(name.into(), Property::UChar((i * 100 + k) as u8));
                }
                v
            })
            .collect();
        ply.payload.insert("vertex".into(), vertices);
        let mut bytes = Vec::new();
        ply_rs::writer::Writer::new()
            .write_ply(&mut bytes, &mut ply)
            .unwrap();
        let cloud = read_ply_bytes(Path::new("ply_rs.ply"), &bytes, &ReadOptions::default())
            .unwrap_or_else(|e| panic!("{encoding:?}: {e}"));
        let expected: Vec<Vec3> = points.iter().map(|p| Vec3::from_array(*p)).collect();
        assert_eq!(bits(&cloud.positions), bits(&expected), "{encoding:?}");
        assert_eq!(
            cloud.colors.unwrap(),
            vec![[0, 1, 2], [100, 101, 102], [200, 201, 202]],
            "{encoding:?}"
        );
    }
    // And ply-rs reads what we write, header and payload.
    let cloud = random_cloud(20, true, true);
    let labels: Vec<u32> = (0..20).collect();
    let opts = WriteOptions {
        colors: true,
        labels: Some(("bone".into(), labels)),
    };
    let mut bytes = Vec::new();
    write_ply_to(&mut bytes, &cloud, &opts).unwrap();
    let ply = ply_rs::parser::Parser::<DefaultElement>::new()
        .read_ply(&mut bytes.as_slice())
        .unwrap();
    assert_eq!(ply.header.encoding, Encoding::BinaryLittleEndian);
    let vertices = &ply.payload["vertex"];
    assert_eq!(vertices.len(), 20);
    for (i, v) in vertices.iter().enumerate() {
        assert_eq!(v["x"], Property::Float(cloud.positions[i].x));
        assert_eq!(
            v["nz"],
            Property::Float(cloud.normals.as_ref().unwrap()[i].z)
        );
        assert_eq!(
            v["blue"],
            Property::UChar(cloud.colors.as_ref().unwrap()[i][2])
        );
        assert_eq!(v["bone"], Property::Int(i as i32));
    }
    // A label name ply-rs could not read back is refused.
    let opts = WriteOptions {
        colors: true,
        labels: Some(("2nd".into(), vec![0; 20])),
    };
    let e = write_ply_to(&mut Vec::new(), &cloud, &opts).unwrap_err();
    assert!(matches!(e, PlyProblem::Inconsistent(_)), "{e}");
}

#[test]
fn non_finite_points_can_be_dropped() {
    let dir = scratch("cloud_ply_drop");
    let text = "ply\nformat ascii 1.0\nelement vertex 6\nproperty float x\nproperty float y\n\
                property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
                end_header\n\
                0 0 0 0 0 1\nnan 0 0 0 0 1\n1 1 1 0 1 0\n2 inf 2 1 0 0\n3 3 3 0 0 NaN\n4 4 4 1 0 0\n";
    let path = write_file(&dir, "some_nan.ply", text.as_bytes());
    let e = read_ply(&path).unwrap_err();
    assert!(
        matches!(e.problem, PlyProblem::NonFinite { count: 3 }),
        "{e}"
    );
    let opts = ReadOptions {
        drop_non_finite: true,
        ..ReadOptions::default()
    };
    let cloud = read_ply_with(&path, &opts).unwrap();
    assert_eq!(
        cloud.positions,
        vec![Vec3::ZERO, Vec3::ONE, Vec3::splat(4.0)]
    );
    assert_eq!(cloud.normals.unwrap(), vec![Vec3::Z, Vec3::Y, Vec3::X]);
    // Labels follow the dropped points.
    let (_, nz) = read_ply_with_property(&path, &opts, "nz").unwrap();
    assert_eq!(nz, vec![1.0, 0.0, 0.0]);
}

// ------------------------------------------------------------------------------------------
// Error corpus
// ------------------------------------------------------------------------------------------

type Check = fn(&PlyProblem) -> bool;

struct Case {
    name: &'static str,
    bytes: Vec<u8>,
    options: ReadOptions,
    check: Check,
    /// Text the message must contain besides the file name.
    says: &'static str,
}

fn case(name: &'static str, bytes: impl Into<Vec<u8>>, check: Check, says: &'static str) -> Case {
    Case {
        name,
        bytes: bytes.into(),
        options: ReadOptions::default(),
        check,
        says,
    }
}

fn corpus() -> Vec<Case> {
    let le = "binary_little_endian";
    let xyz = |format: &str, n: u64| {
        format!(
            "ply\nformat {format} 1.0\nelement vertex {n}\nproperty float x\nproperty float y\n\
             property float z\nend_header\n"
        )
    };
    let mut cases = vec![
        case(
            "empty",
            Vec::new(),
            |p| matches!(p, PlyProblem::EmptyFile),
            "empty",
        ),
        case(
            "obj_file",
            "# OBJ\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n",
            |p| matches!(p, PlyProblem::NotPly),
            "not a PLY",
        ),
        case(
            "random_binary",
            vec![0u8, 159, 146, 150, 255, 10, 0, 1],
            |p| matches!(p, PlyProblem::NotPly),
            "not a PLY",
        ),
        case(
            "garbled_element_line",
            "ply\nformat ascii 1.0\nelement vertex\nproperty float x\nend_header\n",
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "line 3",
        ),
        case(
            "garbled_property_line",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float\nend_header\n0\n",
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "line 4",
        ),
        case(
            "unknown_keyword",
            "ply\nformat ascii 1.0\nelement vertex 1\nproprety float x\nend_header\n0\n",
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "proprety",
        ),
        case(
            "unknown_type",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float128 x\nend_header\n0\n",
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "float128",
        ),
        case(
            "negative_element_count",
            "ply\nformat ascii 1.0\nelement vertex -5\nproperty float x\nend_header\n",
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "-5",
        ),
        case(
            "property_before_element",
            "ply\nformat ascii 1.0\nproperty float x\nelement vertex 1\nend_header\n",
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "before any element",
        ),
        case(
            "missing_end_header",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
             property float z\n0 0 0\n",
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "end_header",
        ),
        case(
            "ply_then_garbage",
            [&b"ply\n"[..], &[7u8, 200, 13, 0, 99, 255][..]].concat(),
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "line 2",
        ),
        case(
            "unknown_format",
            xyz("binary_middle_endian", 1),
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "unknown format",
        ),
        case(
            "no_format_line",
            "ply\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n\
             end_header\n0 0 0\n",
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "format",
        ),
        case(
            "no_vertex_element",
            "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
             end_header\n3 0 1 2\n",
            |p| matches!(p, PlyProblem::NoVertexElement),
            "vertex",
        ),
        case(
            "vertex_without_x",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty float y\nproperty float z\n\
             end_header\n0 0\n",
            |p| matches!(p, PlyProblem::MissingCoordinate("x")),
            "\"x\"",
        ),
        case(
            "x_is_a_list",
            "ply\nformat ascii 1.0\nelement vertex 1\nproperty list uchar float x\n\
             property float y\nproperty float z\nend_header\n1 0 0 0\n",
            |p| matches!(p, PlyProblem::BadHeader(_)),
            "list",
        ),
        case(
            "vertex_count_zero",
            xyz("ascii", 0),
            |p| matches!(p, PlyProblem::Empty),
            "no points",
        ),
    ];

    // Binary: header declares 5000 vertices, the data holds 12.
    let mut b = Bytes::new(&xyz(le, 5000), false);
    for i in 0..12 {
        b.f32s(&[i as f32, 0.0, 1.0]);
    }
    cases.push(case(
        "binary_count_exceeds_data",
        b.take(),
        |p| {
            matches!(
                p,
                PlyProblem::CountExceedsData {
                    declared: 5000,
                    available: 12,
                    ..
                }
            )
        },
        "5000",
    ));
    // Binary: u32::MAX vertices in a tiny file (must fail before allocating).
    let mut b = Bytes::new(&xyz(le, u32::MAX as u64), false);
    b.f32s(&[0.0, 0.0, 0.0]);
    cases.push(case(
        "binary_four_billion_vertices",
        b.take(),
        |p| {
            matches!(
                p,
                PlyProblem::CountExceedsData {
                    declared: 4294967295,
                    available: 1,
                    ..
                }
            )
        },
        "4294967295",
    ));
    // Binary: the last of 3 records cut in the middle.
    let mut b = Bytes::new(&xyz(le, 3), false);
    b.f32s(&[0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 2.0, 2.0]);
    let mut bytes = b.take();
    bytes.pop();
    cases.push(case(
        "binary_truncated_mid_record",
        bytes,
        |p| {
            matches!(
                p,
                PlyProblem::CountExceedsData {
                    declared: 3,
                    available: 2,
                    ..
                }
            )
        },
        "file truncated?",
    ));
    // Binary: a face element before the vertices, cut in the middle of its second list.
    let faces_first = "ply\nformat binary_little_endian 1.0\nelement face 2\n\
                       property list uchar int vertex_indices\nelement vertex 1\n\
                       property float x\nproperty float y\nproperty float z\nend_header\n";
    let mut b = Bytes::new(faces_first, false);
    b.u8(3).i32(0).i32(0).i32(0).u8(4).i32(0).i32(0);
    cases.push(case(
        "binary_face_list_truncated",
        b.take(),
        |p| matches!(p, PlyProblem::Truncated { element, read: 1, declared: 2 } if element == "face"),
        "1 of the 2 face",
    ));
    // Binary: a negative list length in a face element before the vertices.
    let signed_faces = faces_first.replace("list uchar int", "list char int");
    let mut b = Bytes::new(&signed_faces, false);
    b.i8(3).i32(0).i32(0).i32(0).i8(-7).f32s(&[0.0; 8]);
    cases.push(case(
        "binary_negative_list_length",
        b.take(),
        |p| {
            matches!(p, PlyProblem::BadListLength { element, index: 1, length: -7 } if element == "face")
        },
        "-7",
    ));
    // Binary: a list length of four billion before the vertices.
    let huge_faces = faces_first.replace("list uchar int", "list uint int");
    let mut b = Bytes::new(&huge_faces, false);
    b.u32(4_000_000_000).f32s(&[0.0; 12]);
    cases.push(case(
        "binary_huge_list_length",
        b.take(),
        |p| {
            matches!(
                p,
                PlyProblem::Truncated {
                    read: 0,
                    declared: 2,
                    ..
                }
            )
        },
        "file truncated?",
    ));
    // Ascii: far more vertices declared than bytes could hold.
    cases.push(case(
        "ascii_count_exceeds_data",
        xyz("ascii", 10) + "0 0 0\n1 1 1\n2 2 2\n",
        |p| {
            matches!(
                p,
                PlyProblem::CountExceedsData {
                    declared: 10,
                    available: 3,
                    ..
                }
            )
        },
        "10 vertex",
    ));
    cases.push(case(
        "ascii_huge_count",
        xyz("ascii", u64::MAX) + "0 0 0\n",
        |p| {
            matches!(
                p,
                PlyProblem::CountExceedsData {
                    declared: u64::MAX,
                    ..
                }
            )
        },
        "18446744073709551615",
    ));
    // Ascii: one record missing (long numbers, so the byte check cannot tell).
    cases.push(case(
        "ascii_truncated",
        xyz("ascii", 4)
            + "1.000000 2.000000 3.000000\n1.000000 2.000000 3.000000\n\
                            1.000000 2.000000 3.000000\n",
        |p| {
            matches!(
                p,
                PlyProblem::Truncated {
                    read: 3,
                    declared: 4,
                    ..
                }
            )
        },
        "3 of the 4 vertex",
    ));
    cases.push(case(
        "ascii_not_a_number",
        xyz("ascii", 3) + "0 0 0\n1.0 abc 3.0\n2 2 2\n",
        |p| matches!(p, PlyProblem::BadValue { line: 9, .. }),
        "line 9",
    ));
    cases.push(case(
        "ascii_negative_list_length",
        "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
         element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n\
         -3 0 1 2\n0 0 0\n",
        |p| matches!(p, PlyProblem::BadListLength { length: -3, .. }),
        "-3",
    ));
    cases.push(case(
        "ascii_three_nans",
        xyz("ascii", 5) + "0 0 0\nnan 0 0\n1 NaN 1\n2 2 2\n3 3 nan\n",
        |p| matches!(p, PlyProblem::NonFinite { count: 3 }),
        "3 points",
    ));
    let mut b = Bytes::new(&xyz(le, 3), false);
    b.f32s(&[
        0.0,
        0.0,
        0.0,
        f32::INFINITY,
        1.0,
        1.0,
        2.0,
        f32::NEG_INFINITY,
        2.0,
    ]);
    cases.push(case(
        "binary_infinities",
        b.take(),
        |p| matches!(p, PlyProblem::NonFinite { count: 2 }),
        "2 points",
    ));
    // A double too large for f32 becomes infinite.
    let header = "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty double x\n\
                  property double y\nproperty double z\nend_header\n";
    let mut b = Bytes::new(header, false);
    b.f64(1e300).f64(0.0).f64(0.0);
    cases.push(case(
        "double_overflows_f32",
        b.take(),
        |p| matches!(p, PlyProblem::NonFinite { count: 1 }),
        "1 point has",
    ));
    let all_nan = xyz("ascii", 2) + "nan nan nan\ninf 0 0\n";
    let mut dropped_all = case(
        "all_points_dropped",
        all_nan,
        |p| matches!(p, PlyProblem::Empty),
        "no points",
    );
    dropped_all.options.drop_non_finite = true;
    cases.push(dropped_all);
    // Zero-length normals with normals required.
    let normals = "ply\nformat ascii 1.0\nelement vertex 3\nproperty float x\nproperty float y\n\
                   property float z\nproperty float nx\nproperty float ny\nproperty float nz\n\
                   end_header\n0 0 0 0 0 0\n1 1 1 0 0 0\n2 2 2 0 0 0\n";
    let mut zero = case(
        "zero_normals",
        normals,
        |p| matches!(p, PlyProblem::ZeroNormals { count: 3 }),
        "3 points",
    );
    zero.options.require_normals = true;
    cases.push(zero);
    let mut missing = case(
        "normals_missing",
        xyz("ascii", 1) + "0 0 0\n",
        |p| matches!(p, PlyProblem::MissingNormals),
        "normals",
    );
    missing.options.require_normals = true;
    cases.push(missing);
    // Headers that ply-rs alone would misread or choke on.
    cases.push(case(
        "count_overflows_u64",
        "ply\nformat ascii 1.0\nelement vertex 99999999999999999999\nproperty float x\n\
         end_header\n",
        |p| matches!(p, PlyProblem::BadHeader(_)),
        "line 3",
    ));
    cases.push(case(
        "version_256",
        xyz("ascii", 1).replace("1.0", "256.0") + "0 0 0\n",
        |p| matches!(p, PlyProblem::BadHeader(_)),
        "unsupported PLY version",
    ));
    cases.push(case(
        "duplicate_property",
        "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\n\
         property float y\nproperty float z\nproperty float x\nend_header\n0000111122223333",
        |p| matches!(p, PlyProblem::BadHeader(_)),
        "line 7: a second property named \"x\"",
    ));
    cases.push(case(
        "duplicate_element",
        "ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\n\
         property float z\nelement face 0\nelement vertex 1\nproperty float x\n\
         property float y\nproperty float z\nend_header\n0 0 0\n1 1 1\n",
        |p| matches!(p, PlyProblem::BadHeader(_)),
        "line 8: a second element named \"vertex\"",
    ));
    cases.push(case(
        "list_count_is_float",
        "ply\nformat ascii 1.0\nelement face 1\nproperty list float int vertex_indices\n\
         element vertex 1\nproperty float x\nproperty float y\nproperty float z\nend_header\n\
         3 0 1 2\n0 0 0\n",
        |p| matches!(p, PlyProblem::BadHeader(_)),
        "line 4",
    ));
    let mut no_end = Bytes::new(&xyz(le, 1000).replace("end_header\n", ""), false);
    for i in 0..1000 {
        no_end.f32s(&[i as f32, 1.0, 2.0]);
    }
    cases.push(case(
        "binary_without_end_header",
        no_end.take(),
        |p| matches!(p, PlyProblem::BadHeader(_)),
        "end_header",
    ));
    cases
}

#[test]
fn error_corpus() {
    let dir = scratch("cloud_ply_corpus");
    let cases = corpus();
    assert!(cases.len() >= 15);
    let mut names = std::collections::HashSet::new();
    for case in &cases {
        assert!(names.insert(case.name), "duplicate case {}", case.name);
        let file = format!("{}.ply", case.name);
        let path = write_file(&dir, &file, &case.bytes);
        let e: PlyError = match read_ply_with(&path, &case.options) {
            Ok(cloud) => panic!(
                "{}: read {} points instead of failing",
                case.name,
                cloud.len()
            ),
            Err(e) => e,
        };
        let message = e.to_string();
        assert!(
            (case.check)(&e.problem),
            "{}: unexpected problem {:?} ({message})",
            case.name,
            e.problem
        );
        assert!(
            message.contains(&file),
            "{}: message does not name the file: {message}",
            case.name
        );
        assert!(
            message.contains(case.says),
            "{}: message lacks {:?}: {message}",
            case.name,
            case.says
        );
        assert_eq!(e.path, path);
        // The in-memory reader agrees.
        let e2 = read_ply_bytes(&path, &case.bytes, &case.options).unwrap_err();
        assert_eq!(e2.to_string(), message);
    }
}

#[test]
fn error_corpus_paths() {
    let dir = scratch("cloud_ply_corpus_paths");
    let e = read_ply(&dir).unwrap_err();
    assert!(matches!(e.problem, PlyProblem::IsDirectory), "{e}");
    assert!(e.to_string().contains("cloud_ply_corpus_paths"), "{e}");

    let missing = dir.join("does_not_exist.ply");
    let e = read_ply(&missing).unwrap_err();
    match &e.problem {
        PlyProblem::Unreadable(io) => assert_eq!(io.kind(), std::io::ErrorKind::NotFound),
        other => panic!("unexpected {other:?}"),
    }
    assert!(e.to_string().contains("does_not_exist.ply"), "{e}");
    // The crate error wraps it and keeps the message.
    let wrapped: pygmalion::Error = e.into();
    assert!(wrapped.to_string().contains("does_not_exist.ply"));
    assert!(std::error::Error::source(&wrapped).is_some());
}

#[test]
fn zero_normals_are_dropped_unless_required() {
    let dir = scratch("cloud_ply_zero_normals");
    let mut cloud = random_cloud(10, true, false);
    cloud.normals.as_mut().unwrap()[4] = Vec3::ZERO;
    let path = dir.join("one_zero.ply");
    write_ply(&path, &cloud, &WriteOptions::default()).unwrap();
    let back = read_ply(&path).unwrap();
    assert!(back.normals.is_none());
    assert_eq!(back.positions, cloud.positions);
    let opts = ReadOptions {
        require_normals: true,
        ..ReadOptions::default()
    };
    let e = read_ply_with(&path, &opts).unwrap_err();
    assert!(
        matches!(e.problem, PlyProblem::ZeroNormals { count: 1 }),
        "{e}"
    );
    assert!(
        e.to_string().contains("1 point has a zero-length normal"),
        "{e}"
    );
}

/// Every prefix of valid files, and every byte replaced by a few values, reads or fails
/// cleanly (no panic, no runaway allocation).
#[test]
fn damaged_files_never_panic() {
    let ascii = "ply\nformat ascii 1.0\nelement face 1\nproperty list uchar int vertex_indices\n\
                 element vertex 2\nproperty float x\nproperty float y\nproperty float z\n\
                 property float nx\nproperty float ny\nproperty float nz\nend_header\n\
                 3 0 1 1\n0 0 0 0 0 1\n1 2 3 0 1 0\n"
        .as_bytes()
        .to_vec();
    let samples = [ascii, binary_mesh(false), binary_mesh(true)];
    let name = Path::new("damaged.ply");
    let options = [
        ReadOptions::default(),
        ReadOptions {
            drop_non_finite: true,
            require_normals: true,
        },
    ];
    let mut outcomes = [0usize; 2];
    for sample in &samples {
        for len in 0..=sample.len() {
            for o in &options {
                outcomes[read_ply_bytes(name, &sample[..len], o).is_ok() as usize] += 1;
            }
        }
        for i in 0..sample.len() {
            for v in [0u8, 1, 0x7f, 0x80, 0xff, b'\n', b' ', b'9', b'-'] {
                let mut damaged = sample.clone();
                damaged[i] = v;
                let r = read_ply_bytes(name, &damaged, &options[0]);
                if let Err(e) = &r {
                    assert!(e.to_string().starts_with("damaged.ply: "));
                }
                outcomes[r.is_ok() as usize] += 1;
            }
        }
    }
    assert!(outcomes[0] > 0 && outcomes[1] > 0, "{outcomes:?}");
}

// ------------------------------------------------------------------------------------------
// Real scans
// ------------------------------------------------------------------------------------------

fn header_vertex_count(path: &Path) -> u64 {
    let bytes = std::fs::read(path).unwrap();
    let head = String::from_utf8_lossy(&bytes[..bytes.len().min(4096)]).into_owned();
    head.lines()
        .find_map(|l| l.strip_prefix("element vertex "))
        .and_then(|n| n.trim().parse().ok())
        .expect("vertex count in header")
}

fn assert_unit_normals(path: &Path, cloud: &PointCloud) {
    let normals = cloud
        .normals
        .as_ref()
        .unwrap_or_else(|| panic!("{}: no normals", path.display()));
    assert_eq!(normals.len(), cloud.len());
    for n in normals {
        assert!(
            (n.length() - 1.0).abs() < 1e-3,
            "{}: normal {n}",
            path.display()
        );
    }
}

#[test]
fn bundled_dancing_girl() {
    let path = statues_dir().join("statue_dancing_girl_thorvaldsen.ply");
    let cloud = read_ply(&path).unwrap();
    assert_eq!(cloud.len(), 60000);
    assert_unit_normals(&path, &cloud);
    let size = cloud.bounding_box().unwrap().size();
    let expected = Vec3::new(0.8079, 1.799, 0.5751);
    assert!(
        (size - expected).abs().max_element() < 1e-3,
        "bounding box size {size}"
    );
    // Writing it again gives the same file content.
    let dir = scratch("cloud_ply_bundled");
    write_ply(dir.join("again.ply"), &cloud, &WriteOptions::default()).unwrap();
    assert_eq!(read_ply(dir.join("again.ply")).unwrap(), cloud);
}

#[test]
fn shared_data_set_reads() {
    for path in shared_plys() {
        let opts = ReadOptions {
            drop_non_finite: false,
            require_normals: true,
        };
        let cloud = read_ply_with(&path, &opts).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            cloud.len() as u64,
            header_vertex_count(&path),
            "{}",
            path.display()
        );
        assert_unit_normals(&path, &cloud);
    }
}
