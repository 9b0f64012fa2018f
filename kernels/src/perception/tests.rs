use super::*;
use rand::{Rng, SeedableRng};

fn cfg(occlusion: bool) -> PerceptionConfig {
    PerceptionConfig {
        radius: 4.0,
        capsule: Capsule {
            half_length: 0.3,
            radius: 0.2,
        },
        occlusion,
        max_neighbours: usize::MAX,
        max_obstacles: usize::MAX,
        front_cone: 60f64.to_radians(),
    }
}

/// A random herd at one agent per 2 BL², random headings, and 12 blocked cells of a 14 × 14
/// obstacle map (also the force kernel's test scene).
pub(crate) fn scene(seed: u64, n: usize) -> (Vec<P2>, Vec<P2>, ObstacleMap) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let side = (2.0 * n as f64).sqrt();
    let pos: Vec<P2> = (0..n)
        .map(|_| [rng.gen_range(0.0..side), rng.gen_range(0.0..side)])
        .collect();
    let head: Vec<P2> = (0..n)
        .map(|_| {
            let a: f64 = rng.gen_range(-3.2..3.2);
            [a.cos(), a.sin()]
        })
        .collect();
    let mut map = ObstacleMap::empty([0.0, 0.0], 1.5, 14, 14);
    for _ in 0..12 {
        let c = rng.gen_range(0..map.blocked.len());
        map.blocked[c] = true;
    }
    (pos, head, map)
}

/// The definition, pair by pair, with no grid and no sorting.
fn brute(pos: &[P2], head: &[P2], map: &ObstacleMap, c: &PerceptionConfig) -> Vec<Vec<u32>> {
    let d2 = |a: P2, b: P2| (a[0] - b[0]).powi(2) + (a[1] - b[1]).powi(2);
    (0..pos.len())
        .map(|i| {
            let mut v: Vec<(f64, u32)> = vec![];
            for j in 0..pos.len() {
                let dij = d2(pos[i], pos[j]);
                if j == i || dij >= c.radius * c.radius {
                    continue;
                }
                let hidden = c.occlusion
                    && ((0..pos.len()).any(|k| {
                        k != i
                            && k != j
                            && d2(pos[i], pos[k]) < dij
                            && c.capsule.blocks(pos[i], pos[j], pos[k], head[k])
                    }) || map.segment_blocked(pos[i], pos[j]));
                if !hidden {
                    v.push((dij, j as u32));
                }
            }
            v.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
            v.into_iter().map(|x| x.1).collect()
        })
        .collect()
}

fn lists(p: &Perception) -> Vec<Vec<u32>> {
    (0..p.n)
        .map(|i| {
            (0..p.k)
                .filter(|&s| p.neighbour_mask[i * p.k + s] == 1)
                .map(|s| p.neighbours[i * p.k + s])
                .collect()
        })
        .collect()
}

#[test]
fn neighbour_lists_match_brute_force_on_random_scenes() {
    for seed in 0..4 {
        for occ in [false, true] {
            let (pos, head, map) = scene(seed, 300);
            let c = cfg(occ);
            let got = perceive(&pos, &head, Some(&map), &c);
            assert_eq!(
                lists(&got),
                brute(&pos, &head, &map, &c),
                "seed {seed} occ {occ}"
            );
            assert_eq!(got.neighbours.len(), got.n * got.k);
        }
    }
}

/// Branch codes, front-cone counts (atan2 bearing) and densities by their definitions, on the
/// brute-force lists.
#[test]
fn branches_front_counts_and_density_match_definitions() {
    for seed in 20..23 {
        let (pos, head, map) = scene(seed, 300);
        let c = cfg(true);
        let got = perceive(&pos, &head, Some(&map), &c);
        let want = brute(&pos, &head, &map, &c);
        for (i, w) in want.iter().enumerate() {
            let off = |j: u32| {
                [
                    pos[j as usize][0] - pos[i][0],
                    pos[j as usize][1] - pos[i][1],
                ]
            };
            let front = w
                .iter()
                .filter(|&&j| bearing(head[i], off(j)) <= c.front_cone)
                .count();
            assert_eq!(got.front_count[i] as usize, front, "agent {i}");
            for (s, &j) in w.iter().enumerate() {
                assert_eq!(
                    got.neighbour_branch[i * got.k + s],
                    branch_of(head[i], off(j))
                );
            }
            let in_range = (0..pos.len())
                .filter(|&j| {
                    let d2 = (pos[j][0] - pos[i][0]).powi(2) + (pos[j][1] - pos[i][1]).powi(2);
                    d2 < 16.0 && (j == i || d2 > 1e-18)
                })
                .count();
            let area = std::f64::consts::PI * 16.0;
            assert_eq!(got.density[i], in_range as f64 / area);
        }
    }
}

#[test]
fn occlusion_hides_some_but_not_all() {
    let (pos, head, map) = scene(11, 400);
    let open = perceive(&pos, &head, Some(&map), &cfg(false));
    let occl = perceive(&pos, &head, Some(&map), &cfg(true));
    let count = |p: &Perception| p.neighbour_mask.iter().map(|&m| m as usize).sum::<usize>();
    assert!(count(&occl) < count(&open));
    assert!(count(&occl) * 3 > count(&open));
}

#[test]
fn obstacle_points_match_brute_force() {
    let (pos, head, map) = scene(5, 200);
    let c = cfg(true);
    let got = perceive(&pos, &head, Some(&map), &c);
    for i in 0..pos.len() {
        let p = pos[i];
        let mut want = vec![];
        for iy in 0..map.ny {
            for ix in 0..map.nx {
                if !map.blocked[iy * map.nx + ix] {
                    continue;
                }
                let q = map.centre(ix, iy);
                let d2 = (q[0] - p[0]).powi(2) + (q[1] - p[1]).powi(2);
                if d2 >= 16.0 || d2 == 0.0 || map.segment_blocked(p, q) {
                    continue;
                }
                let hidden = (0..pos.len()).any(|k| {
                    let dk = (pos[k][0] - p[0]).powi(2) + (pos[k][1] - p[1]).powi(2);
                    k != i && dk < d2 && c.capsule.blocks(p, q, pos[k], head[k])
                });
                if !hidden {
                    want.push(q);
                }
            }
        }
        let mut have: Vec<P2> = (0..got.ko)
            .filter(|&s| got.obstacle_mask[i * got.ko + s] == 1)
            .map(|s| got.obstacle_points[i * got.ko + s])
            .collect();
        let key = |a: &P2, b: &P2| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1]));
        want.sort_by(key);
        have.sort_by(key);
        assert_eq!(have, want, "agent {i}");
    }
}

#[test]
fn front_cone_counts_and_truncation() {
    // Agent 0 at the origin heading +x; agents ahead at 0°, 45°, 90° and behind.
    let pos = vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.5], [-2.0, 0.0]];
    let head = vec![[1.0, 0.0]; 5];
    let mut c = cfg(false);
    let p = perceive(&pos, &head, None, &c);
    assert_eq!(p.front_count[0], 2);
    assert_eq!(&p.neighbours[..4], &[1, 2, 3, 4]);
    c.max_neighbours = 2;
    let p = perceive(&pos, &head, None, &c);
    assert_eq!(p.k, 2);
    assert_eq!(&p.neighbours[..2], &[1, 2]);
    // Truncation keeps the cone count of all visible neighbours.
    assert_eq!(p.front_count[0], 2);
}

#[test]
fn thread_count_does_not_change_the_output() {
    let (pos, head, map) = scene(9, 500);
    let c = cfg(true);
    let one = crate::on_threads(1, || perceive(&pos, &head, Some(&map), &c));
    let two = crate::on_threads(2, || perceive(&pos, &head, Some(&map), &c));
    assert_eq!(one, two);
}

/// A query among the scene sees what the same agent sees in [`perceive`] once it is moved there:
/// its own scene entry is left out, every other agent is a candidate and an occluder as before.
#[test]
fn a_query_among_the_scene_sees_what_the_moved_agent_sees() {
    for occ in [false, true] {
        let (pos, head, map) = scene(31, 200);
        let c = cfg(occ);
        let whole = perceive(&pos, &head, Some(&map), &c);
        let own: Vec<Option<u32>> = (0..pos.len() as u32).map(Some).collect();
        let scene_ = Scene {
            pos: &pos,
            head: &head,
        };
        assert_eq!(perceive_among(scene_, &own, scene_, Some(&map), &c), whole);
        for i in [0usize, 17, 123] {
            let (q, h) = ([pos[i][0] + 0.7, pos[i][1] - 0.4], [0.6, 0.8]);
            let (mut moved, mut mh) = (pos.clone(), head.clone());
            moved[i] = q;
            mh[i] = h;
            let want = perceive(&moved, &mh, Some(&map), &c);
            let query = Scene {
                pos: &[q],
                head: &[h],
            };
            let got = perceive_among(query, &[Some(i as u32)], scene_, Some(&map), &c);
            let row = |p: &Perception, r: usize| -> Vec<(u32, u8)> {
                (0..p.k)
                    .filter(|&s| p.neighbour_mask[r * p.k + s] == 1)
                    .map(|s| (p.neighbours[r * p.k + s], p.neighbour_branch[r * p.k + s]))
                    .collect()
            };
            assert_eq!(row(&got, 0), row(&want, i), "agent {i}, occlusion {occ}");
            assert_eq!(got.front_count[0], want.front_count[i]);
            assert_eq!(got.density[0], want.density[i]);
            let obs = |p: &Perception, r: usize| -> Vec<P2> {
                (0..p.ko)
                    .filter(|&s| p.obstacle_mask[r * p.ko + s] == 1)
                    .map(|s| p.obstacle_points[r * p.ko + s])
                    .collect()
            };
            assert_eq!(obs(&got, 0), obs(&want, i));
        }
    }
}

/// Verlet lists give exactly [`perceive`]'s output (lists, their order, branches, counts,
/// densities, obstacle points) step after step on a moving herd, for skins from 0 to larger
/// than the steps, while agents leave and enter (the herd's size changes, as through open
/// boundaries) and some stand on one spot.
#[test]
fn verlet_lists_give_the_same_perception_as_a_fresh_search() {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(53);
    for skin in [0.0, 0.3, 1.0, 2.5] {
        for occ in [false, true] {
            let (mut pos, mut head, map) = scene(40 + skin as u64, 400);
            let c = cfg(occ);
            let mut lists = NeighbourLists::new(skin);
            for step in 0..40 {
                if step % 13 == 12 {
                    // One agent leaves, two enter at random spots.
                    pos.remove(step % pos.len());
                    head.remove(step % head.len());
                    for _ in 0..2 {
                        pos.push([rng.gen_range(0.0..28.0), rng.gen_range(0.0..28.0)]);
                        head.push([0.0, 1.0]);
                    }
                }
                let got = lists.perceive(&pos, &head, Some(&map), &c);
                let want = perceive(&pos, &head, Some(&map), &c);
                assert_eq!(got, want, "skin {skin}, occlusion {occ}, step {step}");
                for (i, (p, h)) in pos.iter_mut().zip(head.iter_mut()).enumerate() {
                    if i % 7 == 0 {
                        continue;
                    }
                    let a: f64 = rng.gen_range(-0.3..0.3);
                    *h = [
                        h[0] * a.cos() - h[1] * a.sin(),
                        h[0] * a.sin() + h[1] * a.cos(),
                    ];
                    let v = rng.gen_range(0.0..0.12);
                    *p = [p[0] + v * h[0], p[1] + v * h[1]];
                }
            }
            let (builds, steps) = lists.builds_and_steps();
            assert_eq!(steps, 40);
            if skin >= 1.0 {
                assert!(builds < 20, "skin {skin}: {builds} builds in 40 steps");
            }
        }
    }
}

/// A Verlet list run is the same for any thread count.
#[test]
fn verlet_lists_do_not_depend_on_the_thread_count() {
    let (pos, head, map) = scene(9, 500);
    let c = cfg(true);
    let run = |threads: usize| {
        crate::on_threads(threads, || {
            let mut lists = NeighbourLists::new(1.0);
            let moved: Vec<P2> = pos.iter().map(|p| [p[0] + 0.1, p[1]]).collect();
            lists.perceive(&pos, &head, Some(&map), &c);
            lists.perceive(&moved, &head, Some(&map), &c)
        })
    };
    assert_eq!(run(1), run(2));
}
