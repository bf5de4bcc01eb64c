//! The triangle BVH: built on the host with the surface area heuristic over
//! binned centroids, flattened in depth-first order. The kernels walk it
//! nearest child first with a small stack (`geometry::trace_nearest`, each
//! inner node naming its second child); the f64 reference walks it in plain
//! depth-first order by the skip links.

use glam::{Vec3, Vec4};
use slicelight_shaders::types::{GpuBvhNode, GpuTriangle};

/// Triangles a leaf may hold before a split is tried.
const MAX_LEAF: usize = 4;
/// Centroid bins per axis of the SAH sweep.
const BINS: usize = 16;
/// Cost of visiting a node, in triangle tests (the SAH's traversal cost).
const TRAVERSAL_COST: f32 = 1.0;
/// Below this depth the SAH chooses splits; past it (a degenerate mesh)
/// splits are median splits, which bound the depth by log2 of the count:
/// at most `SAH_DEPTH + 32` levels, within the kernels' traversal stack
/// (`geometry::BVH_STACK`).
const SAH_DEPTH: u32 = 32;

/// The flattened tree and the triangles reordered so each leaf's are contiguous.
pub struct Bvh {
    pub nodes: Vec<GpuBvhNode>,
    pub triangles: Vec<GpuTriangle>,
}

#[derive(Clone, Copy)]
struct Aabb {
    lo: Vec3,
    hi: Vec3,
}

impl Aabb {
    const EMPTY: Aabb = Aabb { lo: Vec3::splat(f32::INFINITY), hi: Vec3::splat(f32::NEG_INFINITY) };
    fn grow(self, p: Vec3) -> Aabb {
        Aabb { lo: self.lo.min(p), hi: self.hi.max(p) }
    }
    fn union(self, o: Aabb) -> Aabb {
        Aabb { lo: self.lo.min(o.lo), hi: self.hi.max(o.hi) }
    }
    fn half_area(self) -> f32 {
        let e = (self.hi - self.lo).max(Vec3::ZERO);
        e.x * e.y + e.y * e.z + e.z * e.x
    }
}

/// A triangle as the build sees it (its index into the input, not the
/// triangle itself: the partitions move 32 bytes, not 100).
struct Item {
    bounds: Aabb,
    centroid: Vec3,
    triangle: u32,
}

impl Bvh {
    pub fn build(triangles: Vec<GpuTriangle>) -> Bvh {
        Bvh::build_with(triangles, PARALLEL_ITEMS)
    }

    /// `build`, subtrees of `parallel` triangles or more on two cores.
    fn build_with(triangles: Vec<GpuTriangle>, parallel: usize) -> Bvh {
        let mut items: Vec<Item> = triangles
            .iter()
            .enumerate()
            .map(|(i, t)| {
                let bounds = [t.v0, t.v1, t.v2].iter().fold(Aabb::EMPTY, |b, v| b.grow(v.truncate()));
                Item { bounds, centroid: (bounds.lo + bounds.hi) * 0.5, triangle: i as u32 }
            })
            .collect();
        let mut nodes = Vec::with_capacity(2 * items.len().div_ceil(MAX_LEAF));
        if !items.is_empty() {
            let n = items.len();
            build_node(&mut items, 0, n, 0, parallel, &mut nodes);
        }
        Bvh { nodes, triangles: items.into_iter().map(|i| triangles[i.triangle as usize]).collect() }
    }
}

/// Triangles under a node from which its two subtrees are built on two cores.
const PARALLEL_ITEMS: usize = 8192;

/// Appends the subtree over `items[first..end]` to `nodes` in depth-first
/// order and sets its skip link.
fn build_node(items: &mut [Item], first: usize, end: usize, depth: u32, parallel: usize, nodes: &mut Vec<GpuBvhNode>) {
    let slice = &mut items[first..end];
    let bounds = slice.iter().fold(Aabb::EMPTY, |b, i| b.union(i.bounds));
    let index = nodes.len();
    nodes.push(padded_node(bounds));
    let split = if slice.len() <= MAX_LEAF { None } else { choose_split(slice, bounds, depth) };
    match split {
        None => {
            nodes[index].first = first as u32;
            nodes[index].count = slice.len() as u32;
        }
        Some(mid) if slice.len() >= parallel => {
            // The two subtrees on two cores, each into its own list (links
            // from its own start), then appended with their links moved:
            // the same nodes as the serial order.
            let (left, right) = slice.split_at_mut(mid);
            let subtree = |part: &mut [Item]| {
                let mut own = Vec::new();
                build_node(part, 0, part.len(), depth + 1, parallel, &mut own);
                own
            };
            let (l, r) = rayon::join(|| subtree(left), || subtree(right));
            append(nodes, l, first);
            nodes[index].right = nodes.len() as u32;
            append(nodes, r, first + mid);
        }
        Some(mid) => {
            build_node(items, first, first + mid, depth + 1, parallel, nodes);
            nodes[index].right = nodes.len() as u32;
            build_node(items, first + mid, end, depth + 1, parallel, nodes);
        }
    }
    nodes[index].skip = nodes.len() as u32;
}

/// Appends a subtree built into its own list (links from its start, leaves
/// from item 0) for items from `first` on.
fn append(nodes: &mut Vec<GpuBvhNode>, part: Vec<GpuBvhNode>, first: usize) {
    let offset = nodes.len() as u32;
    nodes.extend(part.into_iter().map(|mut n| {
        n.skip += offset;
        if n.count > 0 {
            n.first += first as u32;
        } else {
            n.right += offset;
        }
        n
    }));
}

/// Partitions `items` and returns the size of the first part, or `None` if
/// a leaf is cheaper (SAH) or the items cannot be told apart.
fn choose_split(items: &mut [Item], bounds: Aabb, depth: u32) -> Option<usize> {
    let cb = items.iter().fold(Aabb::EMPTY, |b, i| b.grow(i.centroid));
    let extent = cb.hi - cb.lo;
    if extent.max_element() <= 0.0 {
        // Every centroid in one point: split by index so leaves stay small.
        return Some(items.len() / 2);
    }
    if depth >= SAH_DEPTH {
        let axis = extent.max_position();
        let mid = items.len() / 2;
        items.select_nth_unstable_by(mid, |a, b| a.centroid[axis].total_cmp(&b.centroid[axis]));
        return Some(mid);
    }
    let mut best: Option<(f32, usize, usize)> = None; // (cost, axis, last bin of the left part)
    let bin_of = |c: Vec3, axis: usize| (((c[axis] - cb.lo[axis]) / extent[axis] * BINS as f32) as usize).min(BINS - 1);
    // The three axes' bins in one pass over the items.
    let mut counts = [[0usize; BINS]; 3];
    let mut boxes = [[Aabb::EMPTY; BINS]; 3];
    // (`bin_of`'s arithmetic on the three axes at once: the same IEEE
    // operations, so the same bins.)
    let (lo, ext) = (glam::Vec3A::from(cb.lo), glam::Vec3A::from(extent));
    for it in items.iter() {
        let f = (glam::Vec3A::from(it.centroid) - lo) / ext * BINS as f32;
        for axis in 0..3 {
            let b = (f[axis] as usize).min(BINS - 1);
            counts[axis][b] += 1;
            boxes[axis][b] = boxes[axis][b].union(it.bounds);
        }
    }
    for axis in 0..3 {
        if extent[axis] <= 0.0 {
            continue;
        }
        let (counts, boxes) = (&counts[axis], &boxes[axis]);
        // Sweep: right-side areas and counts from the top, then the left.
        let mut right_area = [0.0f32; BINS];
        let mut right_count = [0usize; BINS];
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for b in (1..BINS).rev() {
            acc = acc.union(boxes[b]);
            n += counts[b];
            right_area[b] = acc.half_area();
            right_count[b] = n;
        }
        let (mut acc, mut n) = (Aabb::EMPTY, 0);
        for b in 0..BINS - 1 {
            acc = acc.union(boxes[b]);
            n += counts[b];
            if n == 0 || right_count[b + 1] == 0 {
                continue;
            }
            let cost = acc.half_area() * n as f32 + right_area[b + 1] * right_count[b + 1] as f32;
            if best.is_none_or(|(c, _, _)| cost < c) {
                best = Some((cost, axis, b));
            }
        }
    }
    let (cost, axis, last) = best?;
    let leaf_cost = items.len() as f32;
    let split_cost = TRAVERSAL_COST + cost / bounds.half_area().max(1e-30);
    if split_cost >= leaf_cost && items.len() <= 4 * MAX_LEAF {
        return None;
    }
    let threshold = |c: Vec3| bin_of(c, axis) <= last;
    let mut mid = 0;
    for i in 0..items.len() {
        if threshold(items[i].centroid) {
            items.swap(i, mid);
            mid += 1;
        }
    }
    Some(mid)
}

/// A node over `b`, its box padded by 1e-4 of its extent plus 1e-6 of its
/// distance from the origin so that a flat box (a quad's) has a thickness
/// f32 rounding of the slab test cannot slip through.
fn padded_node(b: Aabb) -> GpuBvhNode {
    let pad = (b.hi - b.lo).max_element() * 1e-4 + 1e-6 * (1.0 + b.lo.abs().max(b.hi.abs()).max_element());
    GpuBvhNode {
        bounds_min: (b.lo - Vec3::splat(pad)).extend(0.0),
        bounds_max: (b.hi + Vec3::splat(pad)).extend(0.0),
        first: 0,
        count: 0,
        skip: 0,
        right: 0,
    }
}

/// Depth of the deepest leaf (1 for a single leaf), from the skip links.
pub fn depth(nodes: &[GpuBvhNode]) -> usize {
    fn walk(nodes: &[GpuBvhNode], i: usize) -> (usize, usize) {
        // Returns (depth of the subtree at i, index after it).
        if nodes[i].count > 0 {
            return (1, nodes[i].skip as usize);
        }
        let (dl, next) = walk(nodes, i + 1);
        let (dr, after) = walk(nodes, next);
        debug_assert_eq!(after, nodes[i].skip as usize);
        (1 + dl.max(dr), after)
    }
    if nodes.is_empty() {
        0
    } else {
        walk(nodes, 0).0
    }
}

/// Whether `p` lies in a node's (padded) box.
pub fn node_contains(node: &GpuBvhNode, p: Vec4) -> bool {
    p.truncate().cmpge(node.bounds_min.truncate()).all() && p.truncate().cmple(node.bounds_max.truncate()).all()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random_triangles(n: usize) -> Vec<GpuTriangle> {
        let mut state = 12345u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / (1u64 << 24) as f32
        };
        (0..n)
            .map(|i| {
                let c = Vec3::new(next(), next(), next()) * 10.0;
                GpuTriangle {
                    v0: c.extend(1.0),
                    v1: (c + Vec3::new(0.1, 0.0, 0.0)).extend(1.0),
                    v2: (c + Vec3::new(0.0, 0.1, 0.05)).extend(1.0),
                    object: i as u32,
                    ..Default::default()
                }
            })
            .collect()
    }

    /// Exponentially spaced triangles: each binned SAH split peels off the
    /// farthest few, the deepest tree the build can make.
    fn chain() -> Vec<GpuTriangle> {
        (0..3000)
            .map(|i| {
                let c = Vec3::new(1.02f32.powi(i), 0.0, 0.0);
                GpuTriangle {
                    v0: c.extend(1.0),
                    v1: (c + Vec3::Y).extend(1.0),
                    v2: (c + Vec3::Z).extend(1.0),
                    ..Default::default()
                }
            })
            .collect()
    }

    #[test]
    fn every_triangle_is_in_exactly_one_leaf_inside_every_box_above_it() {
        let bvh = Bvh::build(random_triangles(5000));
        let mut seen = vec![0; bvh.triangles.len()];
        // Walk with an explicit stack of ancestors to check containment.
        fn visit(bvh: &Bvh, i: usize, ancestors: &mut Vec<usize>, seen: &mut [u32]) -> usize {
            let node = bvh.nodes[i];
            if node.count > 0 {
                for t in node.first..node.first + node.count {
                    seen[t as usize] += 1;
                    let tri = bvh.triangles[t as usize];
                    for a in ancestors.iter().chain([&i]) {
                        for v in [tri.v0, tri.v1, tri.v2] {
                            assert!(node_contains(&bvh.nodes[*a], v), "triangle {t} outside node {a}");
                        }
                    }
                }
                return node.skip as usize;
            }
            ancestors.push(i);
            let next = visit(bvh, i + 1, ancestors, seen);
            assert_eq!(node.right as usize, next, "second child of node {i}");
            let after = visit(bvh, next, ancestors, seen);
            ancestors.pop();
            assert_eq!(after, node.skip as usize, "skip link of node {i}");
            after
        }
        let end = visit(&bvh, 0, &mut Vec::new(), &mut seen);
        assert_eq!(end, bvh.nodes.len());
        assert!(seen.iter().all(|&s| s == 1));
        // The SAH keeps a random soup shallow: about log2(5000 / 4) = 10.
        let d = depth(&bvh.nodes);
        assert!(d <= 25, "depth {d}");
    }

    #[test]
    fn subtrees_on_two_cores_give_the_serial_tree() {
        // Random soups and the degenerate chain (median splits past
        // SAH_DEPTH), split onto two cores from 64 triangles up: the same
        // nodes, links and triangle order, bit for bit.
        for triangles in [random_triangles(5000), random_triangles(70), chain()] {
            let serial = Bvh::build_with(triangles.clone(), usize::MAX);
            let parallel = Bvh::build_with(triangles, 64);
            assert_eq!(bytemuck::cast_slice::<_, u8>(&serial.nodes), bytemuck::cast_slice::<_, u8>(&parallel.nodes));
            assert_eq!(
                bytemuck::cast_slice::<_, u8>(&serial.triangles),
                bytemuck::cast_slice::<_, u8>(&parallel.triangles)
            );
        }
    }

    #[test]
    fn degenerate_inputs_build() {
        // All triangles at one point, and one triangle.
        let same: Vec<GpuTriangle> =
            (0..1000).map(|_| GpuTriangle { v1: Vec4::X, v2: Vec4::Y, ..Default::default() }).collect();
        let bvh = Bvh::build(same);
        assert!(depth(&bvh.nodes) <= 12, "depth {}", depth(&bvh.nodes));
        let one = Bvh::build(random_triangles(1));
        assert_eq!(one.nodes.len(), 1);
        assert!(Bvh::build(Vec::new()).nodes.is_empty());
    }

    #[test]
    fn depth_stays_within_the_kernels_stack() {
        // Exponentially spaced triangles: each binned SAH split peels off
        // the farthest few, the deepest tree the build can make; past
        // SAH_DEPTH, median splits bound it.
        let d = depth(&Bvh::build(chain()).nodes);
        assert!(d <= slicelight_shaders::geometry::BVH_STACK, "depth {d}");
    }

    #[test]
    fn nearest_first_walk_finds_what_every_triangle_tested_finds() {
        use slicelight_shaders::geometry::{occluded, ray_triangle, trace_nearest, trace_object, NO_HIT};
        let tris = random_triangles(4000);
        let bvh = Bvh::build(tris);
        let common =
            slicelight_shaders::types::CommonParams { bvh_node_count: bvh.nodes.len() as u32, ..Default::default() };
        let geometry = slicelight_shaders::scene_geometry(&common, &[], &bvh.triangles, &bvh.nodes);
        let mut state = 99u64;
        let mut next = move || {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            ((state >> 40) as f32) / (1u64 << 24) as f32
        };
        let mut hits = 0;
        for k in 0..3000 {
            let o = Vec3::new(next(), next(), next()) * 14.0 - 2.0;
            // Two rays in three toward a triangle (near its centroid), the rest anywhere.
            let t = bvh.triangles[(next() * 3999.0) as usize];
            let aim = (t.v0 + t.v1 + t.v2).truncate() / 3.0 + (Vec3::new(next(), next(), next()) - 0.5) * 0.05;
            let d =
                if k % 3 == 2 { (Vec3::new(next(), next(), next()) - 0.5).normalize() } else { (aim - o).normalize() };
            let brute = |only: Option<u32>| {
                bvh.triangles
                    .iter()
                    .filter(|t| only.is_none_or(|o| t.object == o))
                    .map(|t| ray_triangle(o, d, t.v0.truncate(), t.v1.truncate(), t.v2.truncate(), 0.0))
                    .fold(NO_HIT, f32::min)
            };
            let nearest = brute(None);
            let hit = trace_nearest(o, d, 0.0, NO_HIT, &geometry);
            assert_eq!(hit.distance, nearest, "ray {k}");
            hits += (nearest < NO_HIT) as u32;
            // A shadow ray to just past and just before the nearest hit.
            if nearest < NO_HIT {
                assert!(occluded(o, d, 0.0, nearest * 1.001, &geometry), "ray {k}");
                assert!(!occluded(o, d, 0.0, nearest * 0.999, &geometry), "ray {k}");
            }
            let object = k % 4000;
            assert_eq!(trace_object(o, d, 0.0, NO_HIT, &geometry, object).distance, brute(Some(object)), "ray {k}");
        }
        // Enough of the rays meet something for the comparison to mean something.
        assert!(hits > 1000, "{hits} of 3000 rays hit");
    }
}
