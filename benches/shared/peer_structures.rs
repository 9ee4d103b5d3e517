//! The peers side by side with rayq behind one interface: Embree 3 (its C API declared here, one
//! thread, build quality LOW / MEDIUM / HIGH), obvhs (CWBVH), the `bvh` crate (binary SAH BVH) and
//! rayq's own structures. Shared by `benches/peers.rs` and `examples/evaluate.rs` (feature `peers`),
//! included with `#[path]`.
#![allow(dead_code)]

use std::ffi::CString;

use std::time::Duration;

use rayq::mesh::MeshData;

use rayq::{BuildOptions, Calibration, Hit, Ray, Scene, Structure};

// ---------------------------------------------------------------------------------------------
// Embree 3: the few C functions this bench needs, declared from the installed 3.13 headers
// (rtcore_*.h). Layouts below match RTC_MAX_INSTANCE_LEVEL_COUNT == 1 and RTC_MIN_WIDTH == 0, which
// is how Debian's libembree3 is configured.
// ---------------------------------------------------------------------------------------------
pub mod embree3 {
    use std::ffi::{c_char, c_uint, c_void};

    #[repr(C)]
    pub struct RTCDeviceTy {
        _private: [u8; 0],
    }
    #[repr(C)]
    pub struct RTCSceneTy {
        _private: [u8; 0],
    }
    #[repr(C)]
    pub struct RTCGeometryTy {
        _private: [u8; 0],
    }
    pub type RTCDevice = *mut RTCDeviceTy;
    pub type RTCScene = *mut RTCSceneTy;
    pub type RTCGeometry = *mut RTCGeometryTy;

    pub const RTC_INVALID_GEOMETRY_ID: u32 = u32::MAX;
    pub const RTC_ERROR_NONE: c_uint = 0;
    pub const RTC_BUILD_QUALITY_LOW: c_uint = 0;
    pub const RTC_BUILD_QUALITY_MEDIUM: c_uint = 1;
    pub const RTC_BUILD_QUALITY_HIGH: c_uint = 2;
    /// Embree 3 `RTC_SCENE_FLAG_ROBUST` (rtcore_scene.h: 1 << 2).
    pub const RTC_SCENE_FLAG_ROBUST: c_uint = 1 << 2;
    pub const RTC_GEOMETRY_TYPE_TRIANGLE: c_uint = 0;
    pub const RTC_BUFFER_TYPE_INDEX: c_uint = 0;
    pub const RTC_BUFFER_TYPE_VERTEX: c_uint = 1;
    pub const RTC_FORMAT_UINT3: c_uint = 0x5003;
    pub const RTC_FORMAT_FLOAT3: c_uint = 0x9003;
    pub const RTC_DEVICE_PROPERTY_VERSION: c_uint = 0;
    pub const RTC_DEVICE_PROPERTY_TASKING_SYSTEM: c_uint = 128;
    pub const RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT: c_uint = 0;

    #[repr(C, align(16))]
    #[derive(Clone, Copy)]
    pub struct RTCRay {
        pub org_x: f32,
        pub org_y: f32,
        pub org_z: f32,
        pub tnear: f32,
        pub dir_x: f32,
        pub dir_y: f32,
        pub dir_z: f32,
        pub time: f32,
        pub tfar: f32,
        pub mask: u32,
        pub id: u32,
        pub flags: u32,
    }

    #[repr(C, align(16))]
    #[derive(Clone, Copy)]
    pub struct RTCHit {
        pub ng_x: f32,
        pub ng_y: f32,
        pub ng_z: f32,
        pub u: f32,
        pub v: f32,
        pub prim_id: u32,
        pub geom_id: u32,
        pub inst_id: [u32; 1],
    }

    #[repr(C)]
    #[derive(Clone, Copy)]
    pub struct RTCRayHit {
        pub ray: RTCRay,
        pub hit: RTCHit,
    }

    #[repr(C)]
    pub struct RTCIntersectContext {
        pub flags: c_uint,
        pub filter: Option<unsafe extern "C" fn(*const c_void)>,
        pub inst_id: [u32; 1],
    }

    impl RTCIntersectContext {
        /// What the header's inline `rtcInitIntersectContext` does.
        pub fn new() -> Self {
            RTCIntersectContext {
                flags: RTC_INTERSECT_CONTEXT_FLAG_INCOHERENT,
                filter: None,
                inst_id: [RTC_INVALID_GEOMETRY_ID],
            }
        }
    }

    #[link(name = "embree3")]
    extern "C" {
        pub fn rtcNewDevice(config: *const c_char) -> RTCDevice;
        pub fn rtcReleaseDevice(device: RTCDevice);
        pub fn rtcGetDeviceError(device: RTCDevice) -> c_uint;
        pub fn rtcGetDeviceProperty(device: RTCDevice, prop: c_uint) -> isize;
        pub fn rtcNewScene(device: RTCDevice) -> RTCScene;
        pub fn rtcReleaseScene(scene: RTCScene);
        pub fn rtcSetSceneBuildQuality(scene: RTCScene, quality: c_uint);
        pub fn rtcSetSceneFlags(scene: RTCScene, flags: c_uint);
        pub fn rtcNewGeometry(device: RTCDevice, kind: c_uint) -> RTCGeometry;
        pub fn rtcReleaseGeometry(geometry: RTCGeometry);
        pub fn rtcSetGeometryBuildQuality(geometry: RTCGeometry, quality: c_uint);
        pub fn rtcSetNewGeometryBuffer(
            geometry: RTCGeometry,
            kind: c_uint,
            slot: c_uint,
            format: c_uint,
            byte_stride: usize,
            item_count: usize,
        ) -> *mut c_void;
        pub fn rtcCommitGeometry(geometry: RTCGeometry);
        pub fn rtcAttachGeometry(scene: RTCScene, geometry: RTCGeometry) -> c_uint;
        pub fn rtcCommitScene(scene: RTCScene);
        pub fn rtcIntersect1(
            scene: RTCScene,
            context: *mut RTCIntersectContext,
            rayhit: *mut RTCRayHit,
        );
    }
}

/// An Embree device restricted to one thread.
pub struct EmbreeDevice(embree3::RTCDevice);

impl EmbreeDevice {
    pub fn new() -> Result<EmbreeDevice, String> {
        let config = CString::new("threads=1").unwrap();
        // SAFETY: a valid NUL-terminated config string; a null result is handled.
        let device = unsafe { embree3::rtcNewDevice(config.as_ptr()) };
        if device.is_null() {
            return Err("rtcNewDevice(\"threads=1\") returned NULL".into());
        }
        Ok(EmbreeDevice(device))
    }

    pub fn property(&self, prop: std::ffi::c_uint) -> isize {
        // SAFETY: the device is alive.
        unsafe { embree3::rtcGetDeviceProperty(self.0, prop) }
    }

    /// Embree's version as "major.minor.patch".
    pub fn version(&self) -> String {
        let v = self.property(embree3::RTC_DEVICE_PROPERTY_VERSION);
        format!("{}.{}.{}", v / 10000, v / 100 % 100, v % 100)
    }

    /// A scene of one triangle geometry built at `quality` from the caller's arrays, with
    /// `RTC_SCENE_FLAG_ROBUST` when `robust`.
    pub fn build(
        &self,
        data: &MeshData,
        quality: std::ffi::c_uint,
        robust: bool,
    ) -> Result<EmbreeScene, String> {
        use embree3::*;
        // SAFETY: every handle comes from Embree and is checked; the buffers Embree returns hold
        // exactly `item_count` items of the declared stride (Embree pads vertex buffers itself), so
        // the copies stay in bounds.
        unsafe {
            let scene = rtcNewScene(self.0);
            if scene.is_null() {
                return Err(self.error("rtcNewScene"));
            }
            let scene = EmbreeScene(scene);
            rtcSetSceneBuildQuality(scene.0, quality);
            if robust {
                rtcSetSceneFlags(scene.0, RTC_SCENE_FLAG_ROBUST);
            }
            let geom = rtcNewGeometry(self.0, RTC_GEOMETRY_TYPE_TRIANGLE);
            if geom.is_null() {
                return Err(self.error("rtcNewGeometry"));
            }
            rtcSetGeometryBuildQuality(geom, quality);
            let verts = rtcSetNewGeometryBuffer(
                geom,
                RTC_BUFFER_TYPE_VERTEX,
                0,
                RTC_FORMAT_FLOAT3,
                12,
                data.vertices.len(),
            ) as *mut [f32; 3];
            let tris = rtcSetNewGeometryBuffer(
                geom,
                RTC_BUFFER_TYPE_INDEX,
                0,
                RTC_FORMAT_UINT3,
                12,
                data.indices.len(),
            ) as *mut [u32; 3];
            if verts.is_null() || tris.is_null() {
                rtcReleaseGeometry(geom);
                return Err(self.error("rtcSetNewGeometryBuffer"));
            }
            std::ptr::copy_nonoverlapping(data.vertices.as_ptr(), verts, data.vertices.len());
            std::ptr::copy_nonoverlapping(data.indices.as_ptr(), tris, data.indices.len());
            rtcCommitGeometry(geom);
            rtcAttachGeometry(scene.0, geom);
            rtcReleaseGeometry(geom); // the scene holds its own reference
            rtcCommitScene(scene.0);
            match rtcGetDeviceError(self.0) {
                RTC_ERROR_NONE => Ok(scene),
                e => Err(format!("Embree error {e} while building")),
            }
        }
    }

    fn error(&self, what: &str) -> String {
        // SAFETY: the device is alive.
        let e = unsafe { embree3::rtcGetDeviceError(self.0) };
        format!("{what} failed (Embree error {e})")
    }
}

impl Drop for EmbreeDevice {
    fn drop(&mut self) {
        // SAFETY: released once; scenes hold their own device references.
        unsafe { embree3::rtcReleaseDevice(self.0) }
    }
}

/// A committed Embree scene.
pub struct EmbreeScene(embree3::RTCScene);

impl EmbreeScene {
    /// Closest hit with `rtcIntersect1`: the primitive id (or `Hit::INVALID_ID`) and its `t`.
    #[inline]
    fn intersect(&self, ray: &Ray) -> (u32, f32) {
        use embree3::*;
        let mut rh = RTCRayHit {
            ray: RTCRay {
                org_x: ray.org.x,
                org_y: ray.org.y,
                org_z: ray.org.z,
                tnear: ray.tmin,
                dir_x: ray.dir.x,
                dir_y: ray.dir.y,
                dir_z: ray.dir.z,
                time: 0.0,
                tfar: ray.tmax,
                mask: u32::MAX,
                id: 0,
                flags: 0,
            },
            hit: RTCHit {
                ng_x: 0.0,
                ng_y: 0.0,
                ng_z: 0.0,
                u: 0.0,
                v: 0.0,
                prim_id: RTC_INVALID_GEOMETRY_ID,
                geom_id: RTC_INVALID_GEOMETRY_ID,
                inst_id: [RTC_INVALID_GEOMETRY_ID],
            },
        };
        let mut ctx = RTCIntersectContext::new();
        // SAFETY: a committed scene, an initialised context and ray/hit on the stack.
        unsafe { rtcIntersect1(self.0, &mut ctx, &mut rh) };
        if rh.hit.geom_id == RTC_INVALID_GEOMETRY_ID {
            (Hit::INVALID_ID, f32::INFINITY)
        } else {
            (rh.hit.prim_id, rh.ray.tfar)
        }
    }
}

impl Drop for EmbreeScene {
    fn drop(&mut self) {
        // SAFETY: released once.
        unsafe { embree3::rtcReleaseScene(self.0) }
    }
}

// ---------------------------------------------------------------------------------------------
// obvhs: CWBVH built with a preset, triangles reordered into leaf order (as its examples do), and
// Möller–Trumbore triangles (`obvhs::triangle::Triangle::intersect`).
// ---------------------------------------------------------------------------------------------
pub struct ObvhsScene {
    bvh: obvhs::cwbvh::CwBvh,
    tris: Vec<obvhs::triangle::Triangle>,
}

impl ObvhsScene {
    fn build(data: &MeshData, params: obvhs::BvhBuildParams) -> ObvhsScene {
        let v = |i: u32| -> [f32; 3] { data.vertices[i as usize] };
        let tris: Vec<obvhs::triangle::Triangle> = data
            .indices
            .iter()
            .map(|t| obvhs::triangle::Triangle {
                v0: v(t[0]).into(),
                v1: v(t[1]).into(),
                v2: v(t[2]).into(),
            })
            .collect();
        let bvh =
            obvhs::cwbvh::builder::build_cwbvh_from_tris(&tris, params, &mut Duration::default());
        let tris = bvh
            .primitive_indices
            .iter()
            .map(|&i| tris[i as usize])
            .collect();
        ObvhsScene { bvh, tris }
    }

    /// Closest hit; returns the original primitive id or `Hit::INVALID_ID`.
    #[inline]
    fn intersect(&self, ray: &Ray) -> (u32, f32) {
        let r = obvhs::ray::Ray::new(
            ray.org.to_array().into(),
            ray.dir.to_array().into(),
            ray.tmin,
            ray.tmax,
        );
        let mut hit = obvhs::ray::RayHit::none();
        if self
            .bvh
            .ray_traverse(r, &mut hit, |r, id| self.tris[id].intersect(r))
        {
            (self.bvh.primitive_indices[hit.primitive_id as usize], hit.t)
        } else {
            (Hit::INVALID_ID, f32::INFINITY)
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The `bvh` crate (svenstaro): its binary SAH `Bvh::build` over one shape per triangle (one
// triangle per leaf; single-threaded: the crate's `rayon` feature is off), traversed with its own
// ray type by `nearest_traverse_iterator` (leaves in order of their box's entry distance, so the
// query stops at the first leaf whose box starts beyond the closest hit so far). The triangle test
// is a two-sided Möller–Trumbore over `[tmin, tmax]` written here: the crate's
// `Ray::intersects_triangle` culls back faces, measures `t` along the normalised direction and
// rejects `t <= f32::EPSILON`, none of which matches `rayq::Ray`.
// ---------------------------------------------------------------------------------------------
pub struct BvhTriangle {
    v0: glam::Vec3,
    e1: glam::Vec3,
    e2: glam::Vec3,
    aabb: bvh::aabb::Aabb<f32, 3>,
    /// The triangle's index in the caller's arrays.
    id: u32,
    node_index: usize,
}

impl bvh::aabb::Bounded<f32, 3> for BvhTriangle {
    fn aabb(&self) -> bvh::aabb::Aabb<f32, 3> {
        self.aabb
    }
}

impl bvh::bounding_hierarchy::BHShape<f32, 3> for BvhTriangle {
    fn set_bh_node_index(&mut self, index: usize) {
        self.node_index = index;
    }

    fn bh_node_index(&self) -> usize {
        self.node_index
    }
}

impl BvhTriangle {
    /// Two-sided Möller–Trumbore: the hit's `t` when the ray crosses the closed triangle with
    /// `tmin ≤ t ≤ tmax`.
    #[inline]
    fn intersect(&self, ray: &Ray) -> Option<f32> {
        let p = ray.dir.cross(self.e2);
        let det = self.e1.dot(p);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let inv_det = 1.0 / det;
        let s = ray.org - self.v0;
        let u = s.dot(p) * inv_det;
        if !(0.0..=1.0).contains(&u) {
            return None;
        }
        let q = s.cross(self.e1);
        let v = ray.dir.dot(q) * inv_det;
        if v < 0.0 || u + v > 1.0 {
            return None;
        }
        let t = self.e2.dot(q) * inv_det;
        (t >= ray.tmin && t <= ray.tmax).then_some(t)
    }
}

pub struct BvhScene {
    bvh: bvh::bvh::Bvh<f32, 3>,
    tris: Vec<BvhTriangle>,
}

impl BvhScene {
    fn build(data: &MeshData) -> BvhScene {
        let v = |i: u32| glam::Vec3::from_array(data.vertices[i as usize]);
        let mut tris: Vec<BvhTriangle> = data
            .indices
            .iter()
            .zip(0u32..)
            .map(|(t, id)| {
                let (a, b, c) = (v(t[0]), v(t[1]), v(t[2]));
                let aabb = bvh::aabb::Aabb::with_bounds(
                    a.min(b).min(c).to_array().into(),
                    a.max(b).max(c).to_array().into(),
                );
                BvhTriangle {
                    v0: a,
                    e1: b - a,
                    e2: c - a,
                    aabb,
                    id,
                    node_index: 0,
                }
            })
            .collect();
        let bvh = bvh::bvh::Bvh::build(&mut tris);
        BvhScene { bvh, tris }
    }

    /// Closest hit; returns the original primitive id or `Hit::INVALID_ID`.
    #[inline]
    fn intersect(&self, ray: &Ray) -> (u32, f32) {
        // The crate's ray with the caller's direction as is (`Ray::new` would normalise it), so
        // box distances are in the same units as `tmin`/`tmax`. Its box tests start at t = 0.
        let r = bvh::ray::Ray {
            origin: ray.org.to_array().into(),
            direction: ray.dir.to_array().into(),
            inv_direction: ray.dir.recip().to_array().into(),
        };
        let (mut best_t, mut best) = (ray.tmax, Hit::INVALID_ID);
        for tri in self.bvh.nearest_traverse_iterator(&r, &self.tris) {
            match r.intersection_slice_for_aabb(&tri.aabb) {
                Some((entry, _)) if entry > best_t => break,
                _ => {}
            }
            if let Some(t) = tri.intersect(ray) {
                if t < best_t || best == Hit::INVALID_ID {
                    best_t = t;
                    best = tri.id;
                }
            }
        }
        if best == Hit::INVALID_ID {
            (best, f32::INFINITY)
        } else {
            (best, best_t)
        }
    }
}

// ---------------------------------------------------------------------------------------------
// The structures side by side.
// ---------------------------------------------------------------------------------------------
#[derive(Clone, Copy)]
pub enum Kind {
    Rayq(Structure),
    Embree(std::ffi::c_uint),
    /// Embree with `RTC_SCENE_FLAG_ROBUST` (its watertight-er mode) at a build quality.
    EmbreeRobust(std::ffi::c_uint),
    Obvhs(&'static str, obvhs::BvhBuildParams),
    Bvh,
}

impl Kind {
    pub fn label(&self) -> String {
        match *self {
            Kind::Rayq(Structure::KdTree) => "rayq kd-tree".into(),
            Kind::Rayq(_) => "rayq grid".into(),
            Kind::Embree(q) => format!(
                "Embree {}",
                ["LOW", "MEDIUM", "HIGH"].get(q as usize).unwrap_or(&"?")
            ),
            Kind::EmbreeRobust(q) => format!(
                "Embree {} robust",
                ["LOW", "MEDIUM", "HIGH"].get(q as usize).unwrap_or(&"?")
            ),
            Kind::Obvhs(preset, _) => format!("obvhs {preset}"),
            Kind::Bvh => "bvh crate".into(),
        }
    }

    pub fn build(&self, data: &MeshData, embree: Option<&EmbreeDevice>) -> Result<Built, String> {
        match *self {
            Kind::Rayq(structure) => {
                let options = BuildOptions {
                    structure,
                    ..BuildOptions::DEFAULT
                };
                Scene::build(&data.as_source(), &options, Calibration::builtin())
                    .map(Built::Rayq)
                    .map_err(|e| format!("{e:?}"))
            }
            Kind::Embree(quality) => match embree {
                Some(device) => device.build(data, quality, false).map(Built::Embree),
                None => Err("no Embree device".into()),
            },
            Kind::EmbreeRobust(quality) => match embree {
                Some(device) => device.build(data, quality, true).map(Built::Embree),
                None => Err("no Embree device".into()),
            },
            Kind::Obvhs(_, params) => Ok(Built::Obvhs(ObvhsScene::build(data, params))),
            Kind::Bvh => Ok(Built::Bvh(BvhScene::build(data))),
        }
    }
}

// One value per structure under test: the size difference of the variants does not matter.
#[allow(clippy::large_enum_variant)]
pub enum Built {
    Rayq(Scene),
    Embree(EmbreeScene),
    Obvhs(ObvhsScene),
    Bvh(BvhScene),
}

impl Built {
    /// Traces every ray (closest hit) and returns how many hit. The match is outside the loop so
    /// each structure runs its own monomorphic loop.
    pub fn count_hits(&self, rays: &[Ray]) -> usize {
        match self {
            Built::Rayq(s) => rays.iter().filter(|r| s.intersect(r).is_hit()).count(),
            Built::Embree(s) => rays
                .iter()
                .filter(|r| s.intersect(r).0 != Hit::INVALID_ID)
                .count(),
            Built::Obvhs(s) => rays
                .iter()
                .filter(|r| s.intersect(r).0 != Hit::INVALID_ID)
                .count(),
            Built::Bvh(s) => rays
                .iter()
                .filter(|r| s.intersect(r).0 != Hit::INVALID_ID)
                .count(),
        }
    }

    /// The primitive hit by each ray (`Hit::INVALID_ID` for a miss) and the `t` the structure
    /// reports for it (`+∞` for a miss).
    pub fn hits(&self, rays: &[Ray]) -> Vec<(u32, f32)> {
        match self {
            Built::Rayq(s) => rays
                .iter()
                .map(|r| {
                    let h = s.intersect(r);
                    (h.prim, h.t)
                })
                .collect(),
            Built::Embree(s) => rays.iter().map(|r| s.intersect(r)).collect(),
            Built::Obvhs(s) => rays.iter().map(|r| s.intersect(r)).collect(),
            Built::Bvh(s) => rays.iter().map(|r| s.intersect(r)).collect(),
        }
    }
}
