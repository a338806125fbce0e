//! The Merkle tree one signature covers when a step's puts are sealed
//! together: RFC 9162's (Certificate Transparency's) tree hash over SHA-256,
//! its inclusion paths, and their verification (§2.1.1, §2.1.3.1,
//! §2.1.3.2), so that any reader can check one envelope of the step with
//! the RFC's algorithm and nothing of ours.
//!
//! A leaf is `SHA-256(0x00 ‖ bytes)`, a node `SHA-256(0x01 ‖ left ‖
//! right)`; a tree of `n > 1` leaves splits at the largest power of two
//! below `n`. Each leaf's path lists the sibling hashes from the leaf up.

use sha2::{Digest, Sha256};

/// A SHA-256 hash.
pub(super) type Hash = [u8; 32];

/// The most hashes a path of a tree with `u32` leaves can have.
pub(super) const MAX_PATH: usize = 32;

/// The hash of leaf `bytes`.
pub(super) fn leaf(bytes: &[u8]) -> Hash {
    let mut h = Sha256::new();
    h.update([0x00]);
    h.update(bytes);
    h.finalize().into()
}

fn node(left: &Hash, right: &Hash) -> Hash {
    let mut h = Sha256::new();
    h.update([0x01]);
    h.update(left);
    h.update(right);
    h.finalize().into()
}

/// The largest power of two below `n` (`n > 1`).
fn split(n: usize) -> usize {
    let k = n.next_power_of_two() / 2;
    if k == n {
        k / 2
    } else {
        k
    }
}

/// The root of the tree over `leaves` (at least one) and each leaf's
/// inclusion path: every hash computed once.
pub(super) fn root_and_paths(leaves: &[Hash]) -> (Hash, Vec<Vec<Hash>>) {
    let mut paths = vec![Vec::new(); leaves.len()];
    let root = build(leaves, &mut paths);
    (root, paths)
}

fn build(leaves: &[Hash], paths: &mut [Vec<Hash>]) -> Hash {
    if leaves.len() == 1 {
        return leaves[0];
    }
    let k = split(leaves.len());
    let (left, right) = leaves.split_at(k);
    let (left_paths, right_paths) = paths.split_at_mut(k);
    let l = build(left, left_paths);
    let r = build(right, right_paths);
    // PATH(m, D[n]) = PATH(m, D[0:k]) : MTH(D[k:n]), and the mirror.
    left_paths.iter_mut().for_each(|p| p.push(r));
    right_paths.iter_mut().for_each(|p| p.push(l));
    node(&l, &r)
}

/// The root that leaf `hash`, number `index` of `size`, reaches by `path`
/// (RFC 9162 §2.1.3.2); `None`: the path does not fit the position.
pub(super) fn root_from(index: u64, size: u64, hash: Hash, path: &[Hash]) -> Option<Hash> {
    if index >= size {
        return None;
    }
    let (mut f, mut s, mut r) = (index, size - 1, hash);
    for p in path {
        if s == 0 {
            return None;
        }
        if f & 1 == 1 || f == s {
            r = node(p, &r);
            while f & 1 == 0 && f != 0 {
                f >>= 1;
                s >>= 1;
            }
        } else {
            r = node(&r, p);
        }
        f >>= 1;
        s >>= 1;
    }
    (s == 0).then_some(r)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Certificate Transparency's test leaves.
    const LEAVES: [&str; 8] = [
        "",
        "00",
        "10",
        "2021",
        "3031",
        "40414243",
        "5051525354555657",
        "606162636465666768696a6b6c6d6e6f",
    ];

    /// Their tree hashes for the first 1 to 8 leaves, as published with
    /// RFC 6962's reference implementation.
    const ROOTS: [&str; 8] = [
        "6e340b9cffb37a989ca544e6bb780a2c78901d3fb33738768511a30617afa01d",
        "fac54203e7cc696cf0dfcb42c92a1d9dbaf70ad9e621f4bd8d98662f00e3c125",
        "aeb6bcfe274b70a14fb067a5e5578264db0fa9b51af5e0ba159158f329e06e77",
        "d37ee418976dd95753c1c73862b9398fa2a2cf9b4ff0fdfe8b30cd95209614b7",
        "4e3bbb1f7b478dcfe71fb631631519a3bca12c9aefca1612bfce4c13a86264d4",
        "76e67dadbcdf1e10e1b74ddc608abd2f98dfb16fbce75277b5232a127f2087ef",
        "ddb89be403809e325750d3d263cd78929c2942b7942a34b77e122c9594a74c8c",
        "5dc9da79a70659a9ad559cb701ded9a2ab9d823aad2f4960cfe370eff4604328",
    ];

    fn leaves(n: usize) -> Vec<Hash> {
        LEAVES[..n]
            .iter()
            .map(|h| leaf(&hex::decode(h).unwrap()))
            .collect()
    }

    #[test]
    fn the_roots_are_certificate_transparencys() {
        for (n, want) in ROOTS.iter().enumerate() {
            let (root, _) = root_and_paths(&leaves(n + 1));
            assert_eq!(hex::encode(root), *want, "{} leaves", n + 1);
        }
        // The published path of leaf 5 of 8.
        let (_, paths) = root_and_paths(&leaves(8));
        let path: Vec<String> = paths[5].iter().map(hex::encode).collect();
        assert_eq!(
            path,
            [
                "bc1a0643b12e4d2d7c77918f44e0f4f79a838b6cf9ec5b5c283e1f4d88599e6b",
                "ca854ea128ed050b41b35ffc1b87b8eb2bde461e9e3b5596ece6b9d5975a0ae0",
                "d37ee418976dd95753c1c73862b9398fa2a2cf9b4ff0fdfe8b30cd95209614b7",
            ]
        );
    }

    #[test]
    fn every_leaf_of_every_size_reaches_the_root_and_nothing_else_does() {
        for n in 1..=70usize {
            let hashes: Vec<Hash> = (0..n).map(|i| leaf(&i.to_be_bytes())).collect();
            let (root, paths) = root_and_paths(&hashes);
            let size = n as u64;
            for (i, path) in paths.iter().enumerate() {
                let i = i as u64;
                assert_eq!(root_from(i, size, hashes[i as usize], path), Some(root));
                // Another leaf, another position, a path cut short or made
                // longer: not the root. (The size is signed with the root.)
                let other = hashes[(i as usize + 1) % n];
                if n > 1 {
                    assert_ne!(root_from(i, size, other, path), Some(root));
                    assert_ne!(
                        root_from((i + 1) % size, size, hashes[i as usize], path),
                        Some(root)
                    );
                    assert_ne!(
                        root_from(i, size, hashes[i as usize], &path[1..]),
                        Some(root)
                    );
                }
                let mut longer = path.clone();
                longer.push(root);
                assert_ne!(root_from(i, size, hashes[i as usize], &longer), Some(root));
                assert_eq!(root_from(size, size, hashes[i as usize], path), None);
            }
            assert!(paths.iter().all(|p| p.len() <= MAX_PATH));
        }
    }
}
