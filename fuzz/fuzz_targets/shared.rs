//! What the fuzz targets share (included with `#[path]`): one query through the C boundary.

use rayq::capi::*;

/// `rq_scene_intersect` and `rq_scene_occluded` on one ray, checking that they agree; the hit.
///
/// # Safety
/// `scene` is a live handle.
pub unsafe fn query(scene: *const rq_scene, ray: &rq_ray, what: &str) -> rq_hit {
    let mut hit = rq_hit {
        t: 0.0,
        u: 0.0,
        v: 0.0,
        prim: 0,
    };
    // SAFETY: the caller promises a live scene; ray and hit are valid.
    let (h, o) = unsafe {
        (
            rq_scene_intersect(scene, ray, &mut hit),
            rq_scene_occluded(scene, ray),
        )
    };
    assert_eq!(h, o, "{what}: intersect and occluded disagree on {ray:?}");
    assert_eq!(h, hit.prim != RQ_INVALID_ID, "{what}: {hit:?}");
    hit
}
