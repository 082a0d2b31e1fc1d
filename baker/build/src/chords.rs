//! Chords: which new edges between two locked positions a group's simplification may add.
//!
//! Collapsing a vertex next to a locked border often joins two border positions that were not
//! joined before (an "ear" closes). Inside the group such a chord is an ordinary edge, used
//! twice; it becomes a pinch (an edge used four times, docs/INVARIANTS.md §1 (c)) only where
//! another group uses the same edge as well: a non-manifold edge the input did not have, which
//! the validator counts and reports. Forbidding every chord made the first simplification of almost
//! every group fail its border check and run again with more locks and a higher target
//! (nefertiti: 275 runs of the simplifier for 134 groups, each result 60% of its input
//! instead of the 50% aimed at). So a level is simplified in two rounds: first every group may
//! add any chord that is no edge of the level's input ([`Chords::free`]); then the groups that
//! added a chord some lower-numbered group added too ([`conflicted`]) run again, allowed only
//! chords that no other group can have ([`Chords::unshared`]). The result does not depend on
//! the order in which groups finish.

use mres_geom::edges::{edge_ends, edge_key};
use rayon::prelude::*;

/// Per level: the groups using each shared position, and the edges between two shared
/// positions that the level's input already has.
pub struct Chords {
    /// (position id, group) for every position used by two or more groups, sorted.
    users: Vec<(u32, u32)>,
    /// Edge keys (position ids) of the input's edges whose ends are both shared, sorted.
    existing: Vec<u64>,
}

impl Chords {
    /// The chords of a level whose groups are `parts` (lists of cluster indices into `refs`,
    /// the clusters' triangles in welded ids) over a mesh whose welded vertices map to
    /// `position_ids`; `shared(p)` tells a position used by two or more groups.
    pub fn new(
        parts: &[Vec<u32>],
        refs: &[&[u32]],
        position_ids: &[u32],
        shared: impl Fn(u32) -> bool + Sync,
    ) -> Chords {
        // Per group side by side; sorted and deduplicated, so the order does not matter.
        let (users, existing): (Vec<_>, Vec<_>) = parts
            .par_iter()
            .enumerate()
            .map(|(g, part)| {
                let (mut users, mut existing) = (Vec::new(), Vec::new());
                for t in part.iter().flat_map(|&c| refs[c as usize].chunks_exact(3)) {
                    let p = [0, 1, 2].map(|k| position_ids[t[k] as usize]);
                    for k in 0..3 {
                        let (a, b) = (p[k], p[(k + 1) % 3]);
                        if shared(a) {
                            users.push((a, g as u32));
                            if shared(b) {
                                existing.push(edge_key(a, b));
                            }
                        }
                    }
                }
                (users, existing)
            })
            .unzip();
        let (mut users, mut existing) = (users.concat(), existing.concat());
        users.par_sort_unstable();
        users.dedup();
        existing.par_sort_unstable();
        existing.dedup();
        Chords { users, existing }
    }

    /// The groups using position `p` (empty unless shared), ascending.
    fn groups(&self, p: u32) -> &[(u32, u32)] {
        let start = self.users.partition_point(|u| u.0 < p);
        let end = start + self.users[start..].partition_point(|u| u.0 == p);
        &self.users[start..end]
    }

    /// The first round's rule: edge `e` (position ids) may be added unless the level's input
    /// has it (another group keeps it) or an end is on a cell border (`kept`: groups of
    /// another cell, which this level does not see, may hold it). An end on a non-manifold
    /// edge is allowed: every group holding it is one of this level's, so the users above
    /// see it (refusing those chords left most groups of a mesh with scattered duplicate
    /// triangles stuck or at 60–70 % of their input).
    pub fn free(&self, e: u64, kept: impl Fn(u32) -> bool) -> bool {
        let [a, b] = edge_ends(e);
        !kept(a) && !kept(b) && self.existing.binary_search(&e).is_err()
    }

    /// The second round's rule for group `g`: [`Chords::free`], and no other group holds both
    /// ends (a position only `g` uses is in no other group).
    pub fn unshared(&self, g: u32, e: u64, kept: impl Fn(u32) -> bool) -> bool {
        let [a, b] = edge_ends(e);
        let (ga, gb) = (self.groups(a), self.groups(b));
        self.free(e, kept) && !ga.iter().any(|u| u.1 != g && gb.iter().any(|v| v.1 == u.1))
    }
}

/// The groups that must run again: given each group's added chords (`None` for a group that
/// did not simplify), every group that added a chord a lower-numbered group added too.
/// Ascending.
pub fn conflicted(added: &[Option<&[u64]>]) -> Vec<usize> {
    let mut uses: Vec<(u64, usize)> =
        added.iter().enumerate().flat_map(|(g, c)| c.unwrap_or(&[]).iter().map(move |&e| (e, g))).collect();
    uses.sort_unstable();
    let mut out: Vec<usize> = uses.chunk_by(|a, b| a.0 == b.0).flat_map(|run| run[1..].iter().map(|u| u.1)).collect();
    out.sort_unstable();
    out.dedup();
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two groups sharing positions 1, 2 and 3 (a border 1-2-3); group 0 also holds 0, group 1
    /// holds 4; position 5 is shared by group 1 and a third group.
    fn level() -> Chords {
        let parts = vec![vec![0], vec![1], vec![2]];
        let a: &[u32] = &[0, 1, 2, 0, 2, 3];
        let b: &[u32] = &[4, 2, 1, 4, 3, 2, 4, 5, 1];
        let c: &[u32] = &[5, 6, 7];
        let ids: Vec<u32> = (0..8).collect();
        let shared = |p: u32| matches!(p, 1 | 2 | 3 | 5);
        Chords::new(&parts, &[a, b, c], &ids, shared)
    }

    #[test]
    fn chords_of_the_input_or_locked_ends_are_refused_and_shared_ones_only_first() {
        let chords = level();
        let none = |_: u32| false;
        // 1-3 is a new chord between positions groups 0 and 1 both hold: free for both, but
        // in the second round neither may add it.
        assert!(chords.free(edge_key(1, 3), none));
        assert!(!chords.unshared(0, edge_key(1, 3), none) && !chords.unshared(1, edge_key(1, 3), none));
        // 2-3 is already an edge of the input: no group may add it again.
        assert!(!chords.free(edge_key(2, 3), none));
        // 3-5: only group 1 holds both ends (group 0 holds 3, group 2 holds 5).
        assert!(chords.unshared(1, edge_key(3, 5), none));
        // A position locked beyond the level (a cell border) takes no chord.
        assert!(!chords.free(edge_key(1, 3), |p| p == 3));
    }

    #[test]
    fn the_later_groups_adding_the_same_chord_run_again() {
        let (a, b, c) = ([1u64, 5].as_slice(), [2u64, 5].as_slice(), [1u64, 2].as_slice());
        assert_eq!(conflicted(&[Some(a), None, Some(b), Some(c)]), vec![2, 3]);
        assert_eq!(conflicted(&[Some(a), Some(&[])]), Vec::<usize>::new());
    }
}
