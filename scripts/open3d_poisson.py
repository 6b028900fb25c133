"""Open3D's screened Poisson (Kazhdan & Hoppe 2013) on an oriented point PLY,
for scripts/poisson-vs-open3d.sh: the reference that our CGAL-based Poisson is
measured against.

Usage: python open3d_poisson.py POINTS.ply OUT.ply [DEPTH]

Prints one line, "open3d depth D: S s, V vertices", where S is the wall time
of the reconstruction call alone (reading the points, importing Open3D and
writing the mesh are left out, which favours Open3D in the comparison).
Open3D's defaults otherwise: width 0, scale 1.1, no linear fit, all threads;
no density trimming (the mesh is closed, like ours).
"""
import sys
import time

import open3d as o3d


def main() -> None:
    if len(sys.argv) not in (3, 4):
        sys.exit(__doc__)
    points, out = sys.argv[1], sys.argv[2]
    depth = int(sys.argv[3]) if len(sys.argv) == 4 else 9
    cloud = o3d.io.read_point_cloud(points)
    if not cloud.has_points() or not cloud.has_normals():
        sys.exit(f"{points}: no oriented points (needs x y z nx ny nz)")
    o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
    t = time.perf_counter()
    mesh, _densities = o3d.geometry.TriangleMesh.create_from_point_cloud_poisson(cloud, depth=depth)
    seconds = time.perf_counter() - t
    if not o3d.io.write_triangle_mesh(out, mesh):
        sys.exit(f"{out}: could not write the mesh")
    print(f"open3d depth {depth}: {seconds:.3f} s, {len(mesh.vertices)} vertices")


if __name__ == "__main__":
    main()
