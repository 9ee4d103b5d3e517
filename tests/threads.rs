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
    for structure in [Structure::Grid, Structure::KdTree] {
        let options = BuildOptions {
            structure,
            ..BuildOptions::DEFAULT
        };
        let scene = Scene::build(&data.as_source(), &options, Calibration::builtin()).unwrap();
        assert_eq!(scene.report().structure, structure);
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
    }
}
