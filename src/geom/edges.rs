//! Edges of a triangle mesh, counted by how many triangles use them.

/// (boundary, non-manifold): edges used by exactly one triangle, and by more
/// than two. (0, 0) for a closed manifold surface.
pub fn edge_counts(triangles: &[[u32; 3]]) -> (usize, usize) {
    let mut edges: Vec<(u32, u32)> = triangles
        .iter()
        .flat_map(|t| (0..3).map(move |i| (t[i].min(t[(i + 1) % 3]), t[i].max(t[(i + 1) % 3]))))
        .collect();
    edges.sort_unstable();
    let (mut boundary, mut non_manifold) = (0, 0);
    for run in edges.chunk_by(|a, b| a == b) {
        match run.len() {
            1 => boundary += 1,
            2 => {}
            _ => non_manifold += 1,
        }
    }
    (boundary, non_manifold)
}

#[cfg(test)]
mod tests {
    #[test]
    fn closed_open_and_non_manifold() {
        let tetra = [[0, 2, 1], [0, 1, 3], [1, 2, 3], [0, 3, 2]];
        assert_eq!(super::edge_counts(&tetra), (0, 0));
        assert_eq!(super::edge_counts(&tetra[..3]), (3, 0));
        // Three triangles on one edge (0, 1).
        assert_eq!(super::edge_counts(&[[0, 1, 2], [1, 0, 3], [0, 1, 4]]).1, 1);
        assert_eq!(super::edge_counts(&[]), (0, 0));
    }
}
