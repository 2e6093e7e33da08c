//! The kiosk's GPU rendering: the statue's points as lit, oriented splats, its bones as
//! translucent sphere-mesh capsules, and the camera that follows [`OrbitCamera`].
//!
//! ## Splats
//!
//! Each statue with [`SkinnedPoints`] gets a child **points** entity ([`SplatPoints`] on the
//! statue names it): one static [`Mesh`] of 4 vertices per point, each carrying only
//! `4 · point + corner` ([`ATTRIBUTE_SPLAT_INDEX`]) and the point's colour
//! ([`ATTRIBUTE_SPLAT_COLOR`], 4 bytes); two triangles per point. The points' centres and
//! normals live in a storage buffer of the [`SplatMaterial`] (24 bytes a point,
//! [`pack_points`]). Its vertex shader (`render/splat.wgsl`) reads the point's centre and
//! normal there, the corner in `{±1}²` from [`CORNERS`], and moves each corner by `±r` along
//! two axes of the plane orthogonal to the normal, so the quad lies in the point's tangent plane
//! (depth follows the surface, splats of one surface overlap without z-fighting staircases);
//! when the normal is seen nearly edge-on (`|n·v|` below 0.3) the quad turns smoothly to face
//! the camera, so grazing splats do not vanish into slivers. The fragment shader discards the
//! corners outside the unit disc and shades the rest: the albedo (a warm marble, times the
//! scan's colour when it has one), a two-sided, slightly softened Lambert from a key light fixed
//! in **view** space (a turned statue stays lit from the upper left front, as in the CPU
//! renderer), ambient, and a darkening of grazing surfaces (`render.edl`, a cheap stand-in for
//! eye-dome edges). As in the CPU renderer the shading multiplies sRGB values (then converted
//! to linear for the sRGB target), which keeps the contrast of a drawing.
//!
//! **Size.** The world radius is `1.5 · s · render.point_scale` ([`SPLAT_RADIUS_FACTOR`]), with
//! `s = sqrt(A / n)` the mean spacing of `n` points over `A`, half the bounding box's area (as
//! in [`crate::render::auto_point_radius`]); perspective shrinks it with distance, and the
//! shader keeps at least [`MIN_SPLAT_PIXELS`] on screen, so a far statue stays a closed
//! surface.
//!
//! **Updates.** When [`SkinnedPoints::version`] changes, the drawn points are packed into the
//! statue's staging bytes (in place, in parallel: no allocation) and written straight into the
//! storage buffer (`RenderQueue::write_buffer`); the mesh is untouched. An earlier version kept
//! centres and normals as mesh attributes, four copies per point, and rewrote the mesh: Bevy
//! then cloned, interleaved and re-uploaded 144 MB for a million points, 245 ms a frame on an
//! H200 machine (4 frames a second while a statue moved, against 112 standing still; 104
//! with the storage buffer, `bench --only render/`). The mesh
//! has [`NoFrustumCulling`] since its bounds move with the pose. At most `budget.point_budget`
//! points are drawn (the loader already subsamples; a larger buffer is strided), and no more
//! than the device's largest storage binding holds.
//!
//! ## Bones
//!
//! Once a statue has a [`CurrentPose`], each bone of `pose().bones` gets a child entity with
//! [`BoneMarker`] `{ index }`: its [`Transform`] puts the origin at `c1` with local `+Y` along
//! `c1 → c2`; its mesh is the cone tangent to both spheres (rebuilt in place when the bone's
//! length or radii change); two children carry a unit sphere scaled to `r1` at the origin and to
//! `r2` at `(0, |c2 − c1|, 0)`. The [`BoneMaterial`] is translucent orange, drawn without depth
//! test (an x-ray: the bones sit inside the statue) and more opaque towards its silhouettes.
//! Bones are visible while the statue is fitting or binding, while it moves
//! ([`PoseAnimation`]), and whenever [`ShowBones`] is on.
//!
//! **Ghost bones** (the missing parts of a broken statue, [`GhostBone`] entities placed by
//! [`super::restore`]) get the same cone and caps with their own material: pale blue, fainter,
//! and hatched (the shader discards diagonal world-space stripes, [`GHOST_STRIPES`] of the
//! bone's length), always visible while they exist.
//!
//! ## Camera
//!
//! One [`Camera3d`] ([`KioskCamera`], also the default UI camera) whose transform follows
//! [`OrbitCamera`] every frame (`eye()` looking at `focus()`, up `+Y`), with the near plane at
//! 1% of the orbit distance, no tonemapping (the background is exactly `render.background`), and
//! a [`DirectionalLight`] attached to it (for standard materials other plugins may add).
//! Multisampling is on, except on a software renderer (Mesa lavapipe: CI, headless
//! screenshots), where it costs about a quarter of the frame for nothing the splats need.

use super::restore::GhostBone;
use super::{
    BoneMarker, CurrentPose, KioskSet, OrbitCamera, PoseAnimation, Settings, ShowBones,
    SkinnedPoints, StatueState,
};
use crate::anatomy::Posed;
use bevy::asset::{RenderAssetUsages, uuid_handle};
use bevy::camera::visibility::NoFrustumCulling;
use bevy::core_pipeline::tonemapping::Tonemapping;
use bevy::mesh::{
    Indices, MeshVertexAttribute, MeshVertexBufferLayoutRef, PrimitiveTopology,
    VertexAttributeValues,
};
use bevy::pbr::{MaterialPipeline, MaterialPipelineKey};
use bevy::prelude::*;
use bevy::render::render_resource::{
    AsBindGroup, Buffer, BufferDescriptor, BufferUsages, CompareFunction, RenderPipelineDescriptor,
    ShaderType, SpecializedMeshPipelineError, TextureFormat, VertexFormat,
};
use bevy::render::renderer::{RenderAdapterInfo, RenderDevice, RenderQueue};
use bevy::shader::{Shader, ShaderRef};
use bevy::ui::IsDefaultUiCamera;
use rayon::prelude::*;

/// The splat shader (embedded: the binary works from any directory).
pub const SPLAT_SHADER: Handle<Shader> = uuid_handle!("19bab7d5-fd7d-4e21-84ff-7fbcdc66c433");
/// The bone shader (embedded).
pub const BONE_SHADER: Handle<Shader> = uuid_handle!("cfdb4dfd-0f10-4843-b4ab-51b495596039");

/// Per-vertex index of a splat corner: `4 · point + corner` (the point in the storage buffer,
/// the corner in [`CORNERS`]).
pub const ATTRIBUTE_SPLAT_INDEX: MeshVertexAttribute =
    MeshVertexAttribute::new("SplatIndex", 0x7079_676d_5350_4958, VertexFormat::Uint32);

/// Per-vertex sRGB colour of a splat (4 bytes; alpha unused).
pub const ATTRIBUTE_SPLAT_COLOR: MeshVertexAttribute =
    MeshVertexAttribute::new("SplatColor", 0x7079_676d_5350_4c54, VertexFormat::Unorm8x4);

/// Smallest on-screen splat radius, pixels.
pub const MIN_SPLAT_PIXELS: f32 = 0.9;

/// Warm marble (sRGB), the albedo of scans without colours.
pub const STONE: [u8; 3] = [236, 226, 208];

/// Splat radius over the mean point spacing (the CPU renderer uses 1.2 and fills the remaining
/// holes afterwards; the GPU splats are a little larger instead: `exp(−π·1.5²)` ≈ 0.1% of a
/// randomly sampled surface stays uncovered).
pub const SPLAT_RADIUS_FACTOR: f32 = 1.5;

/// Bone colour (sRGB) and base opacity.
pub const BONE_COLOR: [u8; 3] = [255, 140, 40];
pub const BONE_ALPHA: f32 = 0.3;

/// Ghost bone colour (sRGB) and base opacity.
pub const GHOST_COLOR: [u8; 3] = [120, 200, 255];
pub const GHOST_ALPHA: f32 = 0.22;
/// Hatching of ghost bones: stripes per bone length, and the drawn fraction of each.
pub const GHOST_STRIPES: f32 = 6.0;
pub const GHOST_DUTY: f32 = 0.55;

/// Key light direction in view space (towards the light: upper left, in front).
pub const KEY_LIGHT_VIEW: Vec3 = Vec3::new(-0.4, 0.6, 0.7);

/// Sides of the cone and sphere meshes of a bone.
const BONE_SEGMENTS: usize = 24;

/// Points as lit splats, bones, the camera.
pub struct SplatRenderPlugin;

impl Plugin for SplatRenderPlugin {
    fn build(&self, app: &mut App) {
        {
            let mut shaders = app.world_mut().resource_mut::<Assets<Shader>>();
            let _ = shaders.insert(
                SPLAT_SHADER.id(),
                Shader::from_wgsl(
                    include_str!("render/splat.wgsl"),
                    "pygmalion/kiosk/render/splat.wgsl",
                ),
            );
            let _ = shaders.insert(
                BONE_SHADER.id(),
                Shader::from_wgsl(
                    include_str!("render/bone.wgsl"),
                    "pygmalion/kiosk/render/bone.wgsl",
                ),
            );
        }
        app.add_plugins((
            MaterialPlugin::<SplatMaterial>::default(),
            MaterialPlugin::<BoneMaterial>::default(),
        ))
        .add_systems(Startup, setup_view)
        .add_systems(
            Update,
            (
                software_renderer_msaa,
                follow_orbit,
                attach_points,
                update_points,
                update_bones,
                bone_visibility,
                attach_ghost_meshes,
                update_ghost_meshes,
            )
                .chain()
                .in_set(KioskSet::Render),
        );
    }
}

/// The splats' uniform (see `render/splat.wgsl`).
#[derive(Clone, Copy, Debug, ShaderType)]
pub struct SplatParams {
    /// sRGB albedo (times the point colour), 0..1.
    pub base_color: Vec4,
    /// View-space direction towards the key light, ambient in `w`.
    pub key_light: Vec4,
    /// World radius.
    pub radius: f32,
    /// Smallest on-screen radius, pixels.
    pub min_pixels: f32,
    /// `|n·v|` below which splats turn to the camera.
    pub edge_on: f32,
    /// Grazing-angle darkening, 0..1.
    pub edges: f32,
}

/// The splat material: oriented discs from a 4-vertices-per-point mesh whose centres and
/// normals are read from a storage buffer.
#[derive(Asset, TypePath, AsBindGroup, Clone, Debug)]
pub struct SplatMaterial {
    #[uniform(0)]
    pub params: SplatParams,
    /// The drawn points, [`SPLAT_POINT_BYTES`] each (see [`pack_points`]).
    #[storage(1, read_only, buffer)]
    pub points: Buffer,
}

impl Material for SplatMaterial {
    fn vertex_shader() -> ShaderRef {
        SPLAT_SHADER.into()
    }
    fn fragment_shader() -> ShaderRef {
        SPLAT_SHADER.into()
    }
    fn enable_prepass() -> bool {
        false
    }
    fn enable_shadows() -> bool {
        false
    }
    fn specialize(
        _pipeline: &MaterialPipeline,
        descriptor: &mut RenderPipelineDescriptor,
        layout: &MeshVertexBufferLayoutRef,
        _key: MaterialPipelineKey<Self>,
    ) -> Result<(), SpecializedMeshPipelineError> {
        let vertex_layout = layout.0.get_layout(&[
            ATTRIBUTE_SPLAT_INDEX.at_shader_location(0),
            ATTRIBUTE_SPLAT_COLOR.at_shader_location(1),
        ])?;
        descriptor.vertex.buffers = vec![vertex_layout];
        // The quads are built facing either way.
        descriptor.primitive.cull_mode = None;
        Ok(())
    }
}

/// The bones' uniform (see `render/bone.wgsl`).
#[derive(Clone, Copy, Debug, ShaderType)]
pub struct BoneParams {
    /// Linear RGB, base opacity in `w`.
    pub color: Vec4,
    /// View-space direction towards the key light, ambient in `w`.
    pub key_light: Vec4,
    /// Hatching: stripe period in world units in `x` (0: solid), drawn fraction in `y`.
    pub pattern: Vec4,
}

/// Translucent bones drawn over the statue (no depth test).
#[derive(Asset, TypePath, AsBindGroup, Clone, Debug)]
pub struct BoneMaterial {
    #[uniform(0)]
    pub params: BoneParams,
}

impl Material for BoneMaterial {
    fn fragment_shader() -> ShaderRef {
        BONE_SHADER.into()
    }
    fn alpha_mode(&self) -> AlphaMode {
        AlphaMode::Blend
    }
    fn enable_prepass() -> bool {
        false
    }
    fn enable_shadows() -> bool {
        false
    }
    fn specialize(
        _pipeline: &MaterialPipeline,
        descriptor: &mut RenderPipelineDescriptor,
        _layout: &MeshVertexBufferLayoutRef,
        _key: MaterialPipelineKey<Self>,
    ) -> Result<(), SpecializedMeshPipelineError> {
        if let Some(depth) = descriptor.depth_stencil.as_mut() {
            depth.depth_compare = Some(CompareFunction::Always);
            depth.depth_write_enabled = Some(false);
        }
        Ok(())
    }
}

/// The kiosk's 3D camera.
#[derive(Component, Clone, Copy, Debug, Default)]
pub struct KioskCamera;

/// On a statue: its points entity and what it shows.
#[derive(Component, Debug)]
pub struct SplatPoints {
    /// The child entity drawing the splats.
    pub entity: Entity,
    /// Its mesh.
    pub mesh: Handle<Mesh>,
    /// The [`SkinnedPoints::version`] the mesh shows.
    pub version: u64,
    /// The drawn points' indices when the buffer holds more than the point budget.
    pub keep: Option<Vec<u32>>,
    /// Number of drawn points.
    pub count: usize,
    /// World splat radius.
    pub radius: f32,
    /// The drawn points on the GPU (the material's storage buffer).
    pub buffer: Buffer,
    /// Their bytes as last packed, reused for every pose (no allocation per frame).
    pub staging: Vec<u8>,
}

/// On a statue: its bone entities.
#[derive(Component, Debug)]
pub struct BoneRig {
    /// Per bone: the bone entity, its two cap entities, its cone mesh and the shape it has.
    pub bones: Vec<BoneParts>,
    posed: Posed,
}

/// One bone's entities.
#[derive(Debug, Clone)]
pub struct BoneParts {
    pub entity: Entity,
    pub cap1: Entity,
    pub cap2: Entity,
    pub cone: Handle<Mesh>,
    /// `(length, r1, r2)` the cone mesh was built for.
    pub shape: [f32; 3],
}

/// A sphere at one end of a bone.
#[derive(Component, Clone, Copy, Debug)]
pub struct BoneCap;

/// Shared render assets.
#[derive(Resource, Clone, Debug)]
pub struct RenderHandles {
    pub bone_material: Handle<BoneMaterial>,
    pub unit_sphere: Handle<Mesh>,
}

fn linear(c: [u8; 3]) -> Vec3 {
    let l = Color::srgb_u8(c[0], c[1], c[2]).to_linear();
    Vec3::new(l.red, l.green, l.blue)
}

fn setup_view(
    mut commands: Commands,
    settings: Res<Settings>,
    orbit: Res<OrbitCamera>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut bone_materials: ResMut<Assets<BoneMaterial>>,
) {
    let bg = settings.0.render.background;
    commands.insert_resource(ClearColor(Color::srgb_u8(bg[0], bg[1], bg[2])));
    commands
        .spawn((
            KioskCamera,
            Camera3d::default(),
            Tonemapping::None,
            IsDefaultUiCamera,
            orbit_transform(&orbit),
        ))
        .with_child((
            DirectionalLight {
                illuminance: 8_000.0,
                shadow_maps_enabled: false,
                ..default()
            },
            Transform::from_translation(KEY_LIGHT_VIEW).looking_at(Vec3::ZERO, Vec3::Y),
        ));
    let sphere = Sphere::new(1.0)
        .mesh()
        .uv(BONE_SEGMENTS as u32, BONE_SEGMENTS as u32 / 2);
    let c = linear(BONE_COLOR);
    commands.insert_resource(RenderHandles {
        bone_material: bone_materials.add(BoneMaterial {
            params: BoneParams {
                color: c.extend(BONE_ALPHA),
                key_light: KEY_LIGHT_VIEW.normalize().extend(0.45),
                pattern: Vec4::ZERO,
            },
        }),
        unit_sphere: meshes.add(sphere),
    });
}

/// The camera transform for an orbit state.
pub fn orbit_transform(orbit: &OrbitCamera) -> Transform {
    let eye = orbit.eye();
    let focus = orbit.focus();
    if (eye - focus).length_squared() < 1e-12 || !eye.is_finite() || !focus.is_finite() {
        return Transform::from_translation(focus + Vec3::Z);
    }
    Transform::from_translation(eye).looking_at(focus, Vec3::Y)
}

/// On a software renderer (Mesa lavapipe in CI and headless screenshots) multisampling costs
/// more than it gives (the splats' discarded edges are not smoothed by it): it is turned off.
fn software_renderer_msaa(
    mut done: Local<bool>,
    adapter: Option<Res<RenderAdapterInfo>>,
    mut cameras: Query<&mut Msaa, With<KioskCamera>>,
) {
    if *done {
        return;
    }
    let Some(adapter) = adapter else { return };
    *done = true;
    if format!("{:?}", adapter.device_type) == "Cpu" {
        info!("software renderer ({}): multisampling off", adapter.name);
        for mut msaa in &mut cameras {
            *msaa = Msaa::Off;
        }
    }
}

fn follow_orbit(
    orbit: Res<OrbitCamera>,
    mut cameras: Query<(&mut Transform, &mut Projection), With<KioskCamera>>,
) {
    for (mut t, mut projection) in &mut cameras {
        let next = orbit_transform(&orbit);
        if *t != next {
            *t = next;
        }
        if let Projection::Perspective(p) = &mut *projection {
            let near = (orbit.distance * 0.01).clamp(1e-5, 0.1);
            if (p.near - near).abs() > 1e-7 {
                p.near = near;
            }
        }
    }
}

/// The indices drawn out of `n` points under `budget` (`None`: all).
pub fn budget_indices(n: usize, budget: usize) -> Option<Vec<u32>> {
    if budget == 0 || n <= budget {
        return None;
    }
    Some((0..budget).map(|i| (i * n / budget) as u32).collect())
}

/// The corners of a splat quad, in order (two triangles 0-1-2, 0-2-3).
pub const CORNERS: [[f32; 2]; 4] = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]];

/// Bytes of one point in the splats' storage buffer: centre and normal, 6 × `f32`.
pub const SPLAT_POINT_BYTES: usize = 24;

/// Builds the static splat mesh for `points` (the `keep` subset when given): four vertices per
/// drawn point `i`, each carrying `ATTRIBUTE_SPLAT_INDEX = 4·i + corner` (the corner indexes
/// [`CORNERS`]) and the point's colour, and two triangles per point. Positions and normals are
/// not in the mesh: the vertex shader reads them from the storage buffer [`pack_points`] fills,
/// so a new pose uploads 24 bytes per point and the mesh never changes.
pub fn splat_mesh(points: &SkinnedPoints, keep: Option<&[u32]>) -> Mesh {
    let n = keep.map_or(points.positions.len(), |k| k.len());
    let mut mesh = Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::RENDER_WORLD,
    );
    let index: Vec<u32> = (0..4 * n as u32).collect();
    let colors: Vec<[u8; 4]> = match &points.colors {
        Some(c) if c.len() == points.positions.len() => (0..n)
            .flat_map(|i| {
                let j = keep.map_or(i, |k| k[i] as usize);
                let [r, g, b] = c[j];
                [[r, g, b, 255]; 4]
            })
            .collect(),
        _ => vec![[255; 4]; 4 * n],
    };
    let mut indices = Vec::with_capacity(6 * n);
    for i in 0..n as u32 {
        let b = 4 * i;
        indices.extend_from_slice(&[b, b + 1, b + 2, b, b + 2, b + 3]);
    }
    mesh.insert_attribute(ATTRIBUTE_SPLAT_INDEX, index);
    mesh.insert_attribute(
        ATTRIBUTE_SPLAT_COLOR,
        VertexAttributeValues::Unorm8x4(colors),
    );
    mesh.insert_indices(Indices::U32(indices));
    mesh
}

/// Writes the drawn points' centres and normals (the `keep` subset when given) into `dst`, in
/// place, as the splats' storage buffer holds them: per point `x y z nx ny nz`, little-endian
/// `f32` ([`SPLAT_POINT_BYTES`]). False, with nothing written, when `dst` does not have the
/// size of that many points or the normals do not match the positions.
pub fn pack_points(dst: &mut [u8], points: &SkinnedPoints, keep: Option<&[u32]>) -> bool {
    const CHUNK: usize = 4096;
    let n = keep.map_or(points.positions.len(), |k| k.len());
    if dst.len() != SPLAT_POINT_BYTES * n || points.normals.len() != points.positions.len() {
        return false;
    }
    dst.par_chunks_mut(SPLAT_POINT_BYTES * CHUNK)
        .enumerate()
        .for_each(|(c, chunk)| {
            for (q, out) in chunk.chunks_exact_mut(SPLAT_POINT_BYTES).enumerate() {
                let i = c * CHUNK + q;
                let j = keep.map_or(i, |k| k[i] as usize);
                let p = points.positions.get(j).copied().unwrap_or(Vec3::ZERO);
                let m = points.normals.get(j).copied().unwrap_or(Vec3::ZERO);
                for (k, v) in [p.x, p.y, p.z, m.x, m.y, m.z].into_iter().enumerate() {
                    out[4 * k..4 * k + 4].copy_from_slice(&v.to_le_bytes());
                }
            }
        });
    true
}

/// The world splat radius for a set of points.
pub fn splat_radius(positions: &[Vec3], point_scale: f32) -> f32 {
    let r = crate::render::auto_point_radius(positions) / crate::render::AUTO_RADIUS_FACTOR
        * SPLAT_RADIUS_FACTOR;
    let scale = if point_scale.is_finite() && point_scale > 0.0 {
        point_scale
    } else {
        1.0
    };
    if r.is_finite() && r > 0.0 {
        r * scale
    } else {
        1e-3
    }
}

/// Builds the splats of `points` (`None`, with a warning, when their normals do not match):
/// their [`SplatPoints`] (its `entity` and `mesh` left for the caller to fill: a placeholder
/// and the default handle), the static mesh and the material, the points already written to
/// the new storage buffer.
fn build_splats(
    points: &SkinnedPoints,
    cfg: &crate::kiosk::config::KioskConfig,
    device: &RenderDevice,
    queue: &RenderQueue,
) -> Option<(SplatPoints, Mesh, SplatMaterial)> {
    // The storage buffer must fit the device's largest storage binding.
    let fits = device.limits().max_storage_buffer_binding_size as usize / SPLAT_POINT_BYTES;
    let budget = match cfg.budget.point_budget {
        0 => fits,
        b => b.min(fits),
    };
    let keep = budget_indices(points.positions.len(), budget);
    let count = keep.as_ref().map_or(points.positions.len(), |k| k.len());
    let radius = match &keep {
        Some(k) => {
            let sub: Vec<Vec3> = k.iter().map(|&i| points.positions[i as usize]).collect();
            splat_radius(&sub, cfg.render.point_scale)
        }
        None => splat_radius(&points.positions, cfg.render.point_scale),
    };
    let mut staging = vec![0u8; SPLAT_POINT_BYTES * count];
    if !pack_points(&mut staging, points, keep.as_deref()) {
        warn!("the statue's normals do not match its points: not drawn");
        return None;
    }
    let buffer = device.create_buffer(&BufferDescriptor {
        label: Some("pygmalion splat points"),
        size: staging.len().max(SPLAT_POINT_BYTES) as u64,
        usage: BufferUsages::STORAGE | BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    if !staging.is_empty() {
        queue.write_buffer(&buffer, 0, &staging);
    }
    let mesh = splat_mesh(points, keep.as_deref());
    let base = if points.colors.is_some() {
        Vec3::ONE
    } else {
        Vec3::from_array(STONE.map(|c| c as f32 / 255.0))
    };
    let material = SplatMaterial {
        params: SplatParams {
            base_color: base.extend(1.0),
            key_light: KEY_LIGHT_VIEW.normalize().extend(0.3),
            radius,
            min_pixels: MIN_SPLAT_PIXELS,
            edge_on: 0.3,
            edges: if cfg.render.edl { 1.0 } else { 0.0 },
        },
        points: buffer.clone(),
    };
    info!("drawing {count} points as splats of radius {radius:.4}");
    let splats = SplatPoints {
        entity: Entity::PLACEHOLDER,
        mesh: Handle::default(),
        version: points.version,
        keep,
        count,
        radius,
        buffer,
        staging,
    };
    Some((splats, mesh, material))
}

#[allow(clippy::type_complexity)]
fn attach_points(
    mut commands: Commands,
    statues: Query<(Entity, &SkinnedPoints), Without<SplatPoints>>,
    settings: Res<Settings>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<SplatMaterial>>,
) {
    for (statue, points) in &statues {
        let Some((mut splats, mesh, material)) = build_splats(points, &settings.0, &device, &queue)
        else {
            continue;
        };
        splats.mesh = meshes.add(mesh);
        splats.entity = commands
            .spawn((
                Name::new("points"),
                Mesh3d(splats.mesh.clone()),
                MeshMaterial3d(materials.add(material)),
                NoFrustumCulling,
                Transform::default(),
                Visibility::default(),
                ChildOf(statue),
            ))
            .id();
        commands.entity(statue).insert(splats);
    }
}

/// A new pose: the drawn points are packed into the statue's staging bytes (no allocation)
/// and written to its storage buffer, which the GPU reads from its next frame on. Points of
/// another number (a restoration shown or undone) get new splats on the same entity, drawn
/// from this frame on.
#[allow(clippy::too_many_arguments)]
fn update_points(
    mut commands: Commands,
    mut statues: Query<(&SkinnedPoints, &mut SplatPoints)>,
    settings: Res<Settings>,
    device: Res<RenderDevice>,
    queue: Res<RenderQueue>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<SplatMaterial>>,
) {
    for (points, mut splats) in &mut statues {
        if splats.version == points.version {
            continue;
        }
        let splats = &mut *splats;
        splats.version = points.version;
        if pack_points(&mut splats.staging, points, splats.keep.as_deref()) {
            if !splats.staging.is_empty() {
                queue.write_buffer(&splats.buffer, 0, &splats.staging);
            }
            continue;
        }
        let Some((mut fresh, mesh, material)) = build_splats(points, &settings.0, &device, &queue)
        else {
            continue;
        };
        fresh.entity = splats.entity;
        fresh.mesh = meshes.add(mesh);
        commands.entity(fresh.entity).insert((
            Mesh3d(fresh.mesh.clone()),
            MeshMaterial3d(materials.add(material)),
        ));
        *splats = fresh;
    }
}

/// The cone tangent to the spheres `(0, r1)` and `(l·Y, r2)`, open at both ends: positions and
/// normals of `2 · (BONE_SEGMENTS + 1)` vertices (rings at each end). Collapsed to the origin
/// when one sphere contains the other.
pub fn cone_geometry(l: f32, r1: f32, r2: f32, pos: &mut [[f32; 3]], nrm: &mut [[f32; 3]]) {
    let d = if l > 1e-9 { (r1 - r2) / l } else { 2.0 };
    let ok = d.abs() < 1.0 && r1.is_finite() && r2.is_finite() && l.is_finite();
    let c = if ok { (1.0 - d * d).sqrt() } else { 0.0 };
    let (y1, rho1, y2, rho2) = if ok {
        (r1 * d, r1 * c, l + r2 * d, r2 * c)
    } else {
        (0.0, 0.0, 0.0, 0.0)
    };
    for k in 0..=BONE_SEGMENTS {
        let t = std::f32::consts::TAU * k as f32 / BONE_SEGMENTS as f32;
        let (s, co) = t.sin_cos();
        if let (Some(p), Some(n)) = (pos.get_mut(2 * k..2 * k + 2), nrm.get_mut(2 * k..2 * k + 2)) {
            p[0] = [rho1 * co, y1, rho1 * s];
            p[1] = [rho2 * co, y2, rho2 * s];
            let nv = if ok {
                [c * co, d, c * s]
            } else {
                [0.0, 1.0, 0.0]
            };
            n[0] = nv;
            n[1] = nv;
        }
    }
}

/// The cone mesh of a bone (see [`cone_geometry`]).
pub fn cone_mesh(l: f32, r1: f32, r2: f32) -> Mesh {
    let v = 2 * (BONE_SEGMENTS + 1);
    let mut pos = vec![[0.0f32; 3]; v];
    let mut nrm = vec![[0.0f32; 3]; v];
    cone_geometry(l, r1, r2, &mut pos, &mut nrm);
    let mut indices = Vec::with_capacity(6 * BONE_SEGMENTS);
    for k in 0..BONE_SEGMENTS as u32 {
        let (a, b, a2, b2) = (2 * k, 2 * k + 1, 2 * k + 2, 2 * k + 3);
        indices.extend_from_slice(&[a, b, a2, a2, b, b2]);
    }
    Mesh::new(
        PrimitiveTopology::TriangleList,
        RenderAssetUsages::default(),
    )
    .with_inserted_attribute(Mesh::ATTRIBUTE_POSITION, pos)
    .with_inserted_attribute(Mesh::ATTRIBUTE_NORMAL, nrm)
    .with_inserted_indices(Indices::U32(indices))
}

/// Where a bone entity sits: origin at `c1`, local `+Y` along `c1 → c2`.
pub fn bone_transform(c1: Vec3, c2: Vec3) -> Transform {
    let axis = c2 - c1;
    let len = axis.length();
    let rotation = if len > 1e-9 && axis.is_finite() {
        Quat::from_rotation_arc(Vec3::Y, axis / len)
    } else {
        Quat::IDENTITY
    };
    Transform {
        translation: if c1.is_finite() { c1 } else { Vec3::ZERO },
        rotation,
        scale: Vec3::ONE,
    }
}

/// Rewrites a cone mesh of [`cone_mesh`] for a new shape (its vectors reused).
fn reshape_cone(mesh: &mut Mesh, l: f32, r1: f32, r2: f32) {
    let mut pos = Vec::new();
    if let Some(VertexAttributeValues::Float32x3(p)) = mesh.attribute_mut(Mesh::ATTRIBUTE_POSITION)
    {
        pos = std::mem::take(p);
    }
    let mut nrm = Vec::new();
    if let Some(VertexAttributeValues::Float32x3(n)) = mesh.attribute_mut(Mesh::ATTRIBUTE_NORMAL) {
        nrm = std::mem::take(n);
    }
    let v = 2 * (BONE_SEGMENTS + 1);
    pos.resize(v, [0.0; 3]);
    nrm.resize(v, [0.0; 3]);
    cone_geometry(l, r1, r2, &mut pos, &mut nrm);
    mesh.insert_attribute(Mesh::ATTRIBUTE_POSITION, pos);
    mesh.insert_attribute(Mesh::ATTRIBUTE_NORMAL, nrm);
}

fn cap_transform(y: f32, r: f32) -> Transform {
    let r = if r.is_finite() { r.max(0.0) } else { 0.0 };
    Transform::from_xyz(0.0, y, 0.0).with_scale(Vec3::splat(r))
}

#[allow(clippy::type_complexity)]
fn update_bones(
    mut commands: Commands,
    handles: Option<Res<RenderHandles>>,
    mut statues: Query<(Entity, Ref<CurrentPose>, Option<&mut BoneRig>)>,
    mut transforms: Query<&mut Transform>,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    let Some(handles) = handles else { return };
    for (statue, pose, rig) in &mut statues {
        match rig {
            None => {
                let posed = pose.0.pose();
                let mut bones = Vec::with_capacity(posed.bones.len());
                for (index, b) in posed.bones.iter().enumerate() {
                    let l = (b.c2 - b.c1).length();
                    let cone = meshes.add(cone_mesh(l, b.r1, b.r2));
                    let material = MeshMaterial3d(handles.bone_material.clone());
                    let cap1 = commands
                        .spawn((
                            BoneCap,
                            Mesh3d(handles.unit_sphere.clone()),
                            material.clone(),
                            cap_transform(0.0, b.r1),
                        ))
                        .id();
                    let cap2 = commands
                        .spawn((
                            BoneCap,
                            Mesh3d(handles.unit_sphere.clone()),
                            material.clone(),
                            cap_transform(l, b.r2),
                        ))
                        .id();
                    let entity = commands
                        .spawn((
                            Name::new(format!("bone {index}")),
                            BoneMarker { index },
                            Mesh3d(cone.clone()),
                            material,
                            bone_transform(b.c1, b.c2),
                            Visibility::Hidden,
                            ChildOf(statue),
                        ))
                        .add_children(&[cap1, cap2])
                        .id();
                    bones.push(BoneParts {
                        entity,
                        cap1,
                        cap2,
                        cone,
                        shape: [l, b.r1, b.r2],
                    });
                }
                commands.entity(statue).insert(BoneRig { bones, posed });
            }
            Some(mut rig) => {
                if !pose.is_changed() {
                    continue;
                }
                let rig = &mut *rig;
                pose.0.pose_into(&mut rig.posed);
                for (parts, b) in rig.bones.iter_mut().zip(&rig.posed.bones) {
                    let l = (b.c2 - b.c1).length();
                    if let Ok(mut t) = transforms.get_mut(parts.entity) {
                        *t = bone_transform(b.c1, b.c2);
                    }
                    if let Ok(mut t) = transforms.get_mut(parts.cap1) {
                        *t = cap_transform(0.0, b.r1);
                    }
                    if let Ok(mut t) = transforms.get_mut(parts.cap2) {
                        *t = cap_transform(l, b.r2);
                    }
                    let shape = [l, b.r1, b.r2];
                    let scale = l.max(b.r1).max(b.r2).max(1e-9);
                    let moved = shape
                        .iter()
                        .zip(&parts.shape)
                        .any(|(a, b)| (a - b).abs() > 1e-4 * scale);
                    if !moved {
                        continue;
                    }
                    parts.shape = shape;
                    if let Some(mut mesh) = meshes.get_mut(&parts.cone) {
                        reshape_cone(&mut mesh, l, b.r1, b.r2);
                    }
                }
            }
        }
    }
}

/// Whether a statue's bones are drawn.
pub fn bones_visible(show: bool, state: Option<&StatueState>, animating: bool) -> bool {
    show || animating
        || matches!(
            state,
            Some(StatueState::Fitting { .. } | StatueState::Binding)
        )
}

fn bone_visibility(
    show: Res<ShowBones>,
    statues: Query<(&BoneRig, Option<&StatueState>, Has<PoseAnimation>)>,
    mut vis: Query<&mut Visibility, With<BoneMarker>>,
) {
    for (rig, state, animating) in &statues {
        let want = if bones_visible(show.0, state, animating) {
            Visibility::Inherited
        } else {
            Visibility::Hidden
        };
        for parts in &rig.bones {
            if let Ok(mut v) = vis.get_mut(parts.entity)
                && *v != want
            {
                *v = want;
            }
        }
    }
}

/// A ghost bone's drawing: its cone mesh and its two caps.
#[derive(Component, Debug, Clone)]
pub struct GhostParts {
    pub cone: Handle<Mesh>,
    pub cap1: Entity,
    pub cap2: Entity,
    /// `(length, r1, r2)` the cone mesh was built for.
    pub shape: [f32; 3],
}

/// The ghost material for a bone of length `l` (hatched with [`GHOST_STRIPES`] per length).
pub fn ghost_material(l: f32) -> BoneMaterial {
    let period = if l.is_finite() && l > 0.0 {
        l / GHOST_STRIPES
    } else {
        0.0
    };
    BoneMaterial {
        params: BoneParams {
            color: linear(GHOST_COLOR).extend(GHOST_ALPHA),
            key_light: KEY_LIGHT_VIEW.normalize().extend(0.6),
            pattern: Vec4::new(period, GHOST_DUTY, 0.0, 0.0),
        },
    }
}

fn attach_ghost_meshes(
    mut commands: Commands,
    handles: Option<Res<RenderHandles>>,
    ghosts: Query<(Entity, &GhostBone), Without<GhostParts>>,
    mut meshes: ResMut<Assets<Mesh>>,
    mut materials: ResMut<Assets<BoneMaterial>>,
) {
    let Some(handles) = handles else { return };
    for (e, g) in &ghosts {
        let b = g.shape;
        let l = (b.c2 - b.c1).length();
        let cone = meshes.add(cone_mesh(l, b.r1, b.r2));
        let material = MeshMaterial3d(materials.add(ghost_material(l)));
        let cap1 = commands
            .spawn((
                BoneCap,
                Mesh3d(handles.unit_sphere.clone()),
                material.clone(),
                cap_transform(0.0, b.r1),
                ChildOf(e),
            ))
            .id();
        let cap2 = commands
            .spawn((
                BoneCap,
                Mesh3d(handles.unit_sphere.clone()),
                material.clone(),
                cap_transform(l, b.r2),
                ChildOf(e),
            ))
            .id();
        commands.entity(e).insert((
            Mesh3d(cone.clone()),
            material,
            GhostParts {
                cone,
                cap1,
                cap2,
                shape: [l, b.r1, b.r2],
            },
        ));
    }
}

fn update_ghost_meshes(
    mut ghosts: Query<(&GhostBone, &mut GhostParts), Changed<GhostBone>>,
    mut transforms: Query<&mut Transform>,
    mut meshes: ResMut<Assets<Mesh>>,
) {
    for (g, mut parts) in &mut ghosts {
        let b = g.shape;
        let l = (b.c2 - b.c1).length();
        let shape = [l, b.r1, b.r2];
        if shape == parts.shape {
            continue;
        }
        parts.shape = shape;
        if let Some(mut mesh) = meshes.get_mut(&parts.cone) {
            reshape_cone(&mut mesh, l, b.r1, b.r2);
        }
        if let Ok(mut t) = transforms.get_mut(parts.cap1) {
            *t = cap_transform(0.0, b.r1);
        }
        if let Ok(mut t) = transforms.get_mut(parts.cap2) {
            *t = cap_transform(l, b.r2);
        }
    }
}

/// The RGB pixels `(width, height, rgb)` of a captured 8-bit RGBA or BGRA image (a window
/// screenshot), row-major from the top-left corner.
pub fn capture_rgb(image: &Image) -> std::result::Result<(u32, u32, Vec<u8>), String> {
    let (w, h) = (image.width(), image.height());
    let format = image.texture_descriptor.format;
    let bgra = match format {
        TextureFormat::Bgra8Unorm | TextureFormat::Bgra8UnormSrgb => true,
        TextureFormat::Rgba8Unorm | TextureFormat::Rgba8UnormSrgb => false,
        other => return Err(format!("unsupported screen format {other:?}")),
    };
    let Some(data) = image.data.as_ref() else {
        return Err("the capture has no pixels".into());
    };
    let n = w as usize * h as usize;
    if data.len() < 4 * n || n == 0 {
        return Err(format!(
            "the capture has {} bytes for {w}×{h} pixels",
            data.len()
        ));
    }
    let mut rgb = Vec::with_capacity(3 * n);
    for px in data.chunks_exact(4).take(n) {
        if bgra {
            rgb.extend_from_slice(&[px[2], px[1], px[0]]);
        } else {
            rgb.extend_from_slice(&px[..3]);
        }
    }
    Ok((w, h, rgb))
}
