//! The traversed layout: the binary tree collapsed into 8-wide nodes whose child boxes are
//! stored plane by plane (8 boxes tested in one pass of 8-lane arithmetic), and leaves of up to
//! 8 triangles packed in one block, corner coordinates lane by lane (tested at once). A leaf
//! holding a triangle the caller flagged for a hit filter (alpha-tested surfaces) says so in its
//! child reference, and its lanes' flags are kept beside the blocks: a walk learns from a bit it
//! already holds in a register whether it must look further, so unflagged leaves cost nothing.

use super::build::Binary;

/// Children per node.
pub(super) const WIDTH: usize = 8;
/// Triangles per block (one leaf): the lanes of one test.
pub(super) const BLOCK: usize = 8;

/// An 8-wide node: 256 bytes, 4 cache lines.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
pub(super) struct Wide {
    /// Child boxes by plane, `[2 * axis + (0 for min, 1 for max)][child]`. Unused slots hold
    /// an inverted box (min +inf, max -inf), which no ray enters: no separate count is needed.
    pub(super) planes: [[f32; WIDTH]; 6],
    /// Child references, see [`child`].
    pub(super) child: [u32; WIDTH],
}

impl Wide {
    pub(super) const EMPTY: Wide = Wide {
        planes: [
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
            [f32::INFINITY; WIDTH],
            [f32::NEG_INFINITY; WIDTH],
        ],
        child: [0; WIDTH],
    };
}

/// Child references: a node index, or (top bit set) a leaf, which is one triangle block; a
/// leaf with a triangle flagged for the hit filter also has the next bit set.
pub(super) mod child {
    pub const LEAF: u32 = 1 << 31;
    pub const FILTER: u32 = 1 << 30;

    pub fn leaf(block: usize, filtered: bool) -> u32 {
        assert!(block < FILTER as usize, "BVH too large");
        LEAF | if filtered { FILTER } else { 0 } | block as u32
    }
    #[inline(always)]
    pub fn block(c: u32) -> usize {
        (c & !(LEAF | FILTER)) as usize
    }
}

/// A leaf's triangles; a leaf of fewer than 8 repeats its last triangle (the repeat gives the same hit
/// at the same t, and ties keep the lowest lane, so it never changes a result).
#[derive(Clone, Copy, Debug)]
#[repr(C, align(32))]
pub(super) struct Tris {
    /// Corner coordinates, `[corner][axis][lane]`.
    pub(super) v: [[[f32; BLOCK]; 3]; 3],
    /// Index of each lane's triangle in the list given to `Bvh::build`.
    pub(super) id: [u32; BLOCK],
}

impl Tris {
    pub(super) fn triangle(&self, lane: usize) -> [[f32; 3]; 3] {
        self.v.map(|corner| corner.map(|axis| axis[lane]))
    }
}

/// The wide tree: nodes (the root first), triangle blocks, how many stack entries a traversal
/// can need at most, and per block the mask of its lanes whose triangle is flagged for the hit
/// filter (empty when nothing is flagged; read only for leaves whose reference has `FILTER`).
pub(super) struct Collapsed {
    pub(super) nodes: Vec<Wide>,
    pub(super) blocks: Vec<Tris>,
    pub(super) stack: usize,
    pub(super) filter_lanes: Vec<u8>,
}

/// The geometry a collapse reads: corners, triangles, and which triangles are flagged.
pub(super) struct Soup<'a> {
    pub(super) positions: &'a [[f32; 3]],
    pub(super) triangles: &'a [[u32; 3]],
    pub(super) flagged: Option<&'a [bool]>,
}

pub(super) fn collapse(bin: &Binary, soup: &Soup) -> Collapsed {
    let mut out = Collapsed { nodes: Vec::new(), blocks: Vec::new(), stack: 0, filter_lanes: Vec::new() };
    out.stack = node(bin, 0, soup, &mut out);
    if soup.flagged.is_none() {
        out.filter_lanes = Vec::new();
    }
    out
}

/// Makes the wide node for the binary subtree at `at` (its children are the up-to-8 subtrees
/// found by opening the largest interior node first, which keeps the boxes tested per visit
/// the likeliest to be hit); returns the stack entries the subtree can need.
fn node(bin: &Binary, at: usize, soup: &Soup, out: &mut Collapsed) -> usize {
    let mut kids = vec![at];
    while kids.len() < WIDTH {
        let open = kids
            .iter()
            .enumerate()
            .filter(|(_, &k)| bin.nodes[k].count == 0)
            .max_by(|a, b| bin.nodes[*a.1].area().total_cmp(&bin.nodes[*b.1].area()));
        let Some((i, &k)) = open else { break };
        kids[i] = k + 1;
        kids.push(bin.nodes[k].offset as usize);
    }
    let me = out.nodes.len();
    out.nodes.push(Wide::EMPTY);
    // A visit pushes every hit child but the one it goes on with.
    let mut deepest = 0;
    for (slot, &k) in kids.iter().enumerate() {
        let n = &bin.nodes[k];
        for a in 0..3 {
            out.nodes[me].planes[2 * a][slot] = n.min[a];
            out.nodes[me].planes[2 * a + 1][slot] = n.max[a];
        }
        out.nodes[me].child[slot] = if n.count == 0 {
            let c = out.nodes.len() as u32;
            deepest = deepest.max(node(bin, k, soup, out));
            c
        } else {
            leaf(&bin.ids[n.offset as usize..][..n.count as usize], soup, out)
        };
    }
    kids.len() - 1 + deepest
}

fn leaf(ids: &[u32], soup: &Soup, out: &mut Collapsed) -> u32 {
    assert!((1..=BLOCK).contains(&ids.len()), "the build makes leaves of one block");
    const { assert!(BLOCK <= 8, "lane masks are bytes") };
    let mut b = Tris { v: [[[0.0; BLOCK]; 3]; 3], id: [0; BLOCK] };
    let mut flagged = 0u8;
    for lane in 0..BLOCK {
        let id = ids[lane.min(ids.len() - 1)];
        b.id[lane] = id;
        for (c, &v) in soup.triangles[id as usize].iter().enumerate() {
            for a in 0..3 {
                b.v[c][a][lane] = soup.positions[v as usize][a];
            }
        }
        if soup.flagged.is_some_and(|f| f[id as usize]) {
            flagged |= 1 << lane;
        }
    }
    out.blocks.push(b);
    out.filter_lanes.push(flagged);
    child::leaf(out.blocks.len() - 1, flagged != 0)
}
