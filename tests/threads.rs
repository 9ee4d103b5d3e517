//! One scene, many threads: concurrent queries on a shared `Scene` (grid and kd-tree) give exactly
//! the serial answers; and the types a renderer shares between threads are `Send + Sync`, checked
//! at compile time (this file stops compiling if one of them loses it, e.g. by holding a raw
//! pointer or a `Cell`).

mod common;

use common::{bundled, mesh_of, test_rays};
use rayq::{BuildOptions, Calibration, Hit, KdTree, Scene, Structure, UniformGrid};

/// Fails to compile unless `T` is `Send + Sync`.
const fn assert_send_sync<T: Send + Sync>() {}
const _: () = {
    assert_send_sync::<Scene>();
    assert_send_sync::<KdTree>();
    assert_send_sync::<UniformGrid>();
    assert_send_sync::<Calibration>();
    assert_send_sync::<rayq::TriMesh>();
};

const THREADS: usize = 4;

#[test]
fn concurrent_queries_match_serial_ones() {
    let data = bundled("teapot");
    let rays = test_rays(&mesh_of(&data), 48, 2000, 17);
    // Auto with an unknown budget holds the grid and taps its queries (one in 64, written into a
    // shared buffer from every thread).
    for structure in [Structure::Grid, Structure::KdTree, Structure::Auto] {
        let options = BuildOptions {
            structure,
            ..BuildOptions::DEFAULT
        };
        let mut scene = Scene::build(&data.as_source(), &options, Calibration::builtin()).unwrap();
        if structure != Structure::Auto {
            assert_eq!(scene.report().structure, structure);
        }
        let serial: Vec<(Hit, bool)> = rays
            .iter()
            .map(|r| (scene.intersect(r), scene.occluded(r)))
            .collect();
        assert!(serial.iter().filter(|(h, _)| h.is_hit()).count() > 100);
        // Every thread traces every ray, each starting at a different offset so that threads
        // query different parts of the structure at the same moment.
        let answers: Vec<Vec<(Hit, bool)>> = std::thread::scope(|s| {
            let handles: Vec<_> = (0..THREADS)
                .map(|t| {
                    let (scene, rays) = (&scene, &rays);
                    s.spawn(move || {
                        let n = rays.len();
                        let mut out = vec![(Hit::MISS, false); n];
                        for i in 0..n {
                            let j = (i + t * n / THREADS) % n;
                            out[j] = (scene.intersect(&rays[j]), scene.occluded(&rays[j]));
                        }
                        out
                    })
                })
                .collect();
            handles.into_iter().map(|h| h.join().unwrap()).collect()
        });
        for (t, got) in answers.iter().enumerate() {
            for (i, ((g, go), (w, wo))) in got.iter().zip(&serial).enumerate() {
                assert!(
                    g.same_bits(w) && go == wo,
                    "{structure:?} thread {t} ray {i}: {g:?} vs {w:?}"
                );
            }
        }
        // What the threads tapped feeds the next decision; the answers stay the same.
        let traced = (2 * THREADS * rays.len()) as u64;
        scene.update(traced, 0).unwrap();
        for (r, (w, wo)) in rays.iter().zip(&serial) {
            assert!(scene.intersect(r).same_bits(w) && scene.occluded(r) == *wo);
        }
    }
}
