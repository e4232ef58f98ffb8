//! The traversed layout: the binary tree collapsed into 8-wide nodes whose child boxes are
//! stored plane by plane (8 boxes tested in one pass of 8-lane arithmetic), and leaves of up to
//! 8 triangles packed in one block, corner coordinates lane by lane (tested at once). A leaf of
//! at most 4 triangles takes half a block (lanes 0-3, and the next such leaf lanes 4-7; its
//! reference says which): a block is 5 cache lines, the walk mostly waits on them, and on the
//! anchor scene leaves held 4.5 triangles on average (23 910 blocks; 17 707 with halves). A leaf
//! holding a triangle the caller flagged for a hit filter (alpha-tested surfaces) says so in its
//! child reference, and its lanes' flags are kept beside the blocks: a walk learns from a bit it
//! already holds in a register whether it must look further, so unflagged leaves cost nothing.

use super::build::Binary;

/// Children per node.
pub(super) const WIDTH: usize = 8;
/// Triangles per block (one leaf, or two of at most half as many): the lanes of one test.
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
    /// The leaf is one half of its block: lanes 0-3, or with UPPER lanes 4-7.
    pub const HALF: u32 = 1 << 29;
    pub const UPPER: u32 = 1 << 28;

    pub fn leaf(block: usize, filtered: bool) -> u32 {
        assert!(block < UPPER as usize, "BVH too large");
        LEAF | if filtered { FILTER } else { 0 } | block as u32
    }
    #[inline(always)]
    pub fn block(c: u32) -> usize {
        (c & !(LEAF | FILTER | HALF | UPPER)) as usize
    }
    /// The lanes of its block a leaf owns.
    #[inline(always)]
    pub fn lanes(c: u32) -> u32 {
        if c & HALF == 0 { 0xFF } else if c & UPPER == 0 { 0x0F } else { 0xF0 }
    }
}

/// A leaf's triangles; a leaf of fewer than 8 repeats its last triangle (the repeat gives the
/// same hit at the same t, and ties keep the lowest lane, so it never changes a result).
/// Cache-line aligned: 5 lines, which a walk asks for at once.
#[derive(Clone, Copy, Debug)]
#[repr(C, align(64))]
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
    /// A block whose lanes 4-7 are free for the next leaf of at most 4 triangles.
    pub(super) open_half: Option<usize>,
}

/// The geometry a collapse reads: corners, triangles, and which triangles are flagged.
pub(super) struct Soup<'a> {
    pub(super) positions: &'a [[f32; 3]],
    pub(super) triangles: &'a [[u32; 3]],
    pub(super) flagged: Option<&'a [bool]>,
}

/// SAH costs of the wide tree's parts, in units of one 8-box visit: a leaf block's 8-triangle
/// test (on the anchor scene of `tools/bench_bvh.py`, block costs from 0.5 to 2 changed the
/// tree little and the speed within noise).
const C_NODE: f32 = 1.0;
const C_BLOCK: f32 = 1.0;

/// The wide tree of least SAH cost that the binary tree can be cut into (Ylitie, Karras and
/// Laine 2017, "Efficient Incoherent Ray Traversal on GPUs Through Compressed Wide BVHs", §3.1):
/// each binary subtree is costed as one leaf block (if it holds at most 8 references), one wide
/// node, or spread over up to 8 slots of its parent's wide node, bottom up; then the choices are
/// followed from the root. Greedy collapsing (opening the largest child until 8) leaves the
/// bottom nodes half empty; this fills them where it pays.
pub(super) fn collapse(bin: &Binary, soup: &Soup) -> Collapsed {
    let plan = Plan::new(bin);
    let mut out = Collapsed { nodes: Vec::new(), blocks: Vec::new(), stack: 0, filter_lanes: Vec::new(), open_half: None };
    if plan.choice[0][0] == LEAF_CHOICE {
        out.nodes.push(Wide::EMPTY);
        let r = &bin.nodes[0];
        for a in 0..3 {
            out.nodes[0].planes[2 * a][0] = r.min[a];
            out.nodes[0].planes[2 * a + 1][0] = r.max[a];
        }
        out.nodes[0].child[0] = leaf(&bin.ids[r.first as usize..][..r.count as usize], soup, &mut out);
    } else {
        out.nodes.push(Wide::EMPTY);
        out.stack = node(bin, &plan, 0, 0, soup, &mut out);
    }
    if soup.flagged.is_none() {
        out.filter_lanes = Vec::new();
    }
    out
}

/// `choice[k][0]` for binary node k as one slot: `LEAF_CHOICE`, or a wide node whose 8 slots
/// its left child gets that many of. `choice[k][i - 1]` for i >= 2 slots: 0, as i - 1 slots;
/// else that many to the left child, the rest to the right.
struct Plan {
    choice: Vec<[u8; WIDTH]>,
}

const LEAF_CHOICE: u8 = 0;

fn children(bin: &Binary, k: usize) -> (usize, usize) {
    (k + 1, k + 2 * bin.nodes[k + 1].count as usize)
}

impl Plan {
    fn new(bin: &Binary) -> Plan {
        let n = bin.nodes.len();

        // cost[k][i - 1]: least cost of binary subtree k in at most i slots.
        let mut cost = vec![[0f32; WIDTH]; n];
        let mut choice = vec![[0u8; WIDTH]; n];
        for k in (0..n).rev() {
            let node = &bin.nodes[k];
            let area = node.area();
            if node.count == 1 {
                cost[k] = [area * C_BLOCK; WIDTH];
                continue;
            }
            let (l, r) = children(bin, k);
            // dist[j - 1]: the children spread over j slots (j >= 2).
            let mut dist = [f32::INFINITY; WIDTH];
            let mut split = [1u8; WIDTH];
            for j in 2..=WIDTH {
                for m in 1..j {
                    let c = cost[l][m - 1] + cost[r][j - m - 1];
                    if c < dist[j - 1] {
                        dist[j - 1] = c;
                        split[j - 1] = m as u8;
                    }
                }
            }
            let internal = area * C_NODE + dist[WIDTH - 1];
            let leaf = if node.count as usize <= BLOCK { area * C_BLOCK } else { f32::INFINITY };
            // Ties and NaN (overflowed areas) go to the wide node, which any subtree can be.
            let (c1, ch1) = if leaf <= internal { (leaf, LEAF_CHOICE) } else { (internal, split[WIDTH - 1]) };
            cost[k][0] = c1;
            choice[k][0] = ch1;
            for i in 2..=WIDTH {
                if dist[i - 1] < cost[k][i - 2] {
                    cost[k][i - 1] = dist[i - 1];
                    choice[k][i - 1] = split[i - 1];
                } else {
                    cost[k][i - 1] = cost[k][i - 2];
                }
            }
        }
        Plan { choice }
    }

    /// The binary subtrees that fill `i` slots for subtree k.
    fn slots(&self, bin: &Binary, mut k: usize, mut i: usize, out: &mut Vec<usize>) {
        loop {
            while i >= 2 && self.choice[k][i - 1] == 0 {
                i -= 1;
            }
            if i == 1 {
                out.push(k);
                return;
            }
            let m = self.choice[k][i - 1] as usize;
            let (l, r) = children(bin, k);
            self.slots(bin, l, m, out);
            (k, i) = (r, i - m);
        }
    }
}

/// Fills wide node `me` (already allocated) for binary node `at`, which the plan makes a wide
/// node; returns the stack entries the subtree can need. A node's interior children are
/// allocated side by side, and its leaf blocks likewise, before any grandchild: the children a
/// visit prefetches together lie together.
fn node(bin: &Binary, plan: &Plan, at: usize, me: usize, soup: &Soup, out: &mut Collapsed) -> usize {
    let mut kids = Vec::with_capacity(WIDTH);
    let m = plan.choice[at][0] as usize;
    let (l, r) = children(bin, at);
    plan.slots(bin, l, m, &mut kids);
    plan.slots(bin, r, WIDTH - m, &mut kids);
    debug_assert!(kids.len() <= WIDTH);
    for (slot, &k) in kids.iter().enumerate() {
        let n = &bin.nodes[k];
        for a in 0..3 {
            out.nodes[me].planes[2 * a][slot] = n.min[a];
            out.nodes[me].planes[2 * a + 1][slot] = n.max[a];
        }
        out.nodes[me].child[slot] = if plan.choice[k][0] != LEAF_CHOICE {
            out.nodes.push(Wide::EMPTY);
            (out.nodes.len() - 1) as u32
        } else {
            leaf(&bin.ids[n.first as usize..][..n.count as usize], soup, out)
        };
    }
    // A visit pushes every hit child but the one it goes on with.
    let mut deepest = 0;
    for (slot, &k) in kids.iter().enumerate() {
        let c = out.nodes[me].child[slot];
        if c & child::LEAF == 0 {
            deepest = deepest.max(node(bin, plan, k, c as usize, soup, out));
        }
    }
    kids.len() - 1 + deepest
}

/// One block of the triangles of `refs` (a triangle pre-split into several references that
/// landed in the same leaf is stored once).
fn leaf(refs: &[u32], soup: &Soup, out: &mut Collapsed) -> u32 {
    assert!((1..=BLOCK).contains(&refs.len()), "the plan makes leaves of one block");
    const { assert!(BLOCK <= 8, "lane masks are bytes") };
    let mut ids = [0u32; BLOCK];
    let mut n = 0;
    for &id in refs {
        if !ids[..n].contains(&id) {
            ids[n] = id;
            n += 1;
        }
    }
    let ids = &ids[..n];
    let fill = |b: &mut Tris, lanes: std::ops::Range<usize>| {
        let mut flagged = 0u8;
        for (k, lane) in lanes.enumerate() {
            let id = ids[k.min(ids.len() - 1)];
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
        flagged
    };
    if n <= BLOCK / 2 {
        if let Some(bi) = out.open_half.take() {
            let flagged = fill(&mut out.blocks[bi], BLOCK / 2..BLOCK);
            out.filter_lanes[bi] |= flagged;
            return child::leaf(bi, flagged != 0) | child::HALF | child::UPPER;
        }
    }
    let mut b = Tris { v: [[[0.0; BLOCK]; 3]; 3], id: [0; BLOCK] };
    let flagged = fill(&mut b, 0..BLOCK);
    out.blocks.push(b);
    out.filter_lanes.push(flagged);
    if n <= BLOCK / 2 {
        // Lanes 4-7 repeat the leaf until another small leaf takes them.
        out.open_half = Some(out.blocks.len() - 1);
        out.filter_lanes[out.blocks.len() - 1] &= 0x0F;
        return child::leaf(out.blocks.len() - 1, flagged & 0x0F != 0) | child::HALF;
    }
    child::leaf(out.blocks.len() - 1, flagged != 0)
}
