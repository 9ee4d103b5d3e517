//! Mesh input through the C boundary: `rq_scene_build` on arbitrary vertex and index bytes, with an
//! arbitrary stride (12..=75 bytes), structure, memory limit and counts that never claim more data
//! than the input holds. The build must return a status (never panic or crash); a built scene must
//! answer a few rays with `intersect` agreeing with `occluded`, report sane figures and free.
//!
//! Input layout: byte 0 = stride − 12 (mod 64), byte 1 = structure (mod 3) and flags, bytes 2..4 =
//! memory limit in KiB (0 = none), byte 4 = share of the rest given to vertices, then the data.
//!
//!     cargo +nightly fuzz run scene_build corpus/scene_build
#![no_main]

use core::ptr;
use libfuzzer_sys::fuzz_target;

#[path = "shared.rs"]
mod shared;
use rayq::capi::*;

fuzz_target!(|data: &[u8]| {
    let [s, flags, l0, l1, share, rest @ ..] = data else {
        return;
    };
    let stride = 12 + usize::from(s % 64);
    let structure = match flags % 3 {
        0 => rq_structure::RQ_STRUCTURE_AUTO,
        1 => rq_structure::RQ_STRUCTURE_GRID,
        _ => rq_structure::RQ_STRUCTURE_KDTREE,
    };
    // Split the rest between vertex and index bytes; counts never exceed what the bytes hold.
    let split = rest.len() * usize::from(*share) / 256;
    let (vbytes, ibytes) = rest.split_at(split);
    let vertex_count = if vbytes.len() >= 12 {
        (vbytes.len() - 12) / stride + 1
    } else {
        0
    };
    let mut indices: Vec<u32> = ibytes
        .chunks_exact(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    if flags & 0x80 != 0 && vertex_count > 0 {
        // Mostly valid meshes, so the structures get built: indices folded into range (and one
        // value past the end now and then, when flag bit 6 says so).
        let n = vertex_count as u32 + u32::from(flags & 0x40 != 0);
        indices.iter_mut().for_each(|i| *i %= n);
    }
    let triangle_count = indices.len() / 3;
    let mesh = rq_mesh_desc {
        vertices: vbytes.as_ptr().cast(),
        vertex_count,
        vertex_stride: stride,
        indices: indices.as_ptr(),
        triangle_count,
    };
    let mut opts = core::mem::MaybeUninit::<rq_build_options>::uninit();
    // SAFETY: init writes the whole struct.
    let mut opts = unsafe {
        rq_build_options_init(opts.as_mut_ptr());
        opts.assume_init()
    };
    opts.structure = structure;
    opts.expected_rays = if flags & 0x20 != 0 { 1 << 30 } else { 0 };
    opts.memory_limit = usize::from(u16::from_le_bytes([*l0, *l1])) * 1024;
    let mut scene: *mut rq_scene = ptr::null_mut();
    // SAFETY: the arrays are valid for the counts given (checked above); the pointers outlive the call.
    let status = unsafe { rq_scene_build(&mesh, &opts, ptr::null(), &mut scene) };
    if status != rq_status::RQ_STATUS_OK {
        assert!(scene.is_null(), "out-parameter written on failure");
        return;
    }
    assert!(!scene.is_null());
    // Rays from the first vertices towards the others and along the axes.
    let floats: Vec<f32> = vbytes
        .chunks_exact(4)
        .take(24)
        .map(|c| f32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    for w in floats.windows(6).step_by(3) {
        let ray = rq_ray {
            org: [w[0], w[1], w[2]],
            tmin: 0.0,
            dir: [w[3] - w[0], w[4] - w[1], w[5] - w[2]],
            tmax: f32::INFINITY,
        };
        // SAFETY: scene is live.
        let hit = unsafe { shared::query(scene, &ray, "scene_build") };
        let h = hit.prim != RQ_INVALID_ID;
        if h {
            assert!(hit.prim < triangle_count as u32 && hit.t >= 0.0, "{hit:?}");
        }
    }
    // SAFETY: scene came from rq_scene_build and is freed once.
    unsafe { rq_scene_free(scene) };
});
