"""3D model benchmarks: joint update cost against vertex count, OSMesa frame and load times.

    .venv/bin/python bench/bench_model3d.py            # all
    .venv/bin/python bench/bench_model3d.py update     # one of: update, frame

update: one shoulder update as the Engineer model is subdivided from ~9k to ~1M vertices.
    Ours sets the joint and recomputes every link's absolute matrix (what a frame uploads as
    uniforms); the baseline, like the paper's, also transforms the moved links' vertices on
    the CPU (numpy/BLAS) and, in a second column, uploads the positions to the GPU (OSMesa).
frame: median time of one 800x600 frame under OSMesa (render + read back), for the shipped
    model and a ~1M-triangle subdivision of it; and the load time of each (URDF + meshes
    parsed, then uploaded to the GPU once).
"""

from __future__ import annotations

import argparse
import math
import os
import shutil
import statistics
import struct
import tempfile
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

from ocu.render.platform import offscreen_gl_mode

os.environ.setdefault("PYOPENGL_PLATFORM", offscreen_gl_mode())

import numpy as np
import numpy.typing as npt

from ocu.model.mesh import MeshData
from ocu.model.urdf import RobotModel, default_urdf_path, load_urdf
from ocu.render.camera import OrbitCamera
from ocu.render.gl import GL
from ocu.render.offscreen import OffscreenRenderer
from ocu.render.renderer import ModelRenderer, interleave
from ocu.render.scene import build_frame, model_bounds

JOINT = "shoulder"
UPDATE_SPLITS = (1, 2, 3, 4, 6, 8, 11)  # each triangle becomes split**2 triangles
FRAME_SPLIT_FOR_1M_TRIANGLES = 19
FRAME_SIZE = (800, 600)


def subdivide(mesh: MeshData, split: int) -> MeshData:
    """Each triangle cut into split**2 smaller ones (same shape, more vertices)."""
    if split == 1:
        return mesh
    corners = []
    for i in range(split):
        for j in range(split - i):
            corners.append(((i, j), (i + 1, j), (i, j + 1)))
            if i + j < split - 1:
                corners.append(((i + 1, j), (i + 1, j + 1), (i, j + 1)))
    weights = np.array(
        [[(1.0 - (a + b) / split, a / split, b / split) for a, b in tri] for tri in corners]
    ).reshape(-1, 3)  # (3 * split**2, 3) barycentric weights
    triangles = mesh.positions.reshape(-1, 3, 3).astype(np.float64)
    positions = np.einsum("vw,nwd->nvd", weights, triangles).reshape(-1, 3).astype(np.float32)
    per_triangle = len(weights)
    normals = np.repeat(mesh.normals[::3], per_triangle, axis=0)
    colors = np.repeat(mesh.colors[::3], per_triangle, axis=0)
    return MeshData(positions=positions, normals=normals, colors=colors)


def subdivided_model(model: RobotModel, split: int) -> RobotModel:
    """The same robot with every mesh subdivided."""
    meshes = {name: subdivide(mesh, split) for name, mesh in model.meshes.items()}
    return replace(model, tree=model.tree.copy(), meshes=meshes)


def median_seconds(action: Callable[[], object], min_runs: int, min_time_s: float) -> float:
    """Median duration of an action, run at least min_runs times and min_time_s seconds."""
    times: list[float] = []
    started = time.perf_counter()
    while len(times) < min_runs or time.perf_counter() - started < min_time_s:
        begin = time.perf_counter()
        action()
        times.append(time.perf_counter() - begin)
    return statistics.median(times)


def measure_update(model: RobotModel) -> tuple[int, float, float, float]:
    """Moved vertex count and median seconds: ours, CPU baseline, CPU baseline + upload."""
    tree = model.tree
    moved = [link for link in tree.subtree(tree.joint(JOINT).child) if link in model.meshes]
    originals = {link: model.meshes[link].positions for link in moved}
    normals = {link: model.meshes[link].normals for link in moved}
    camera = OrbitCamera.framing(*model_bounds(model))
    angle = [0.0]

    def ours() -> object:
        angle[0] += 0.001
        tree.set_position(JOINT, math.sin(angle[0]))
        return build_frame(model, camera, 4 / 3, live=tree)

    # Output arrays made once, as the paper's loop writes into existing vertex arrays.
    moved_positions = {link: np.empty_like(originals[link]) for link in moved}
    moved_normals = {link: np.empty_like(normals[link]) for link in moved}

    def baseline(upload: Callable[[str, npt.NDArray[np.float32]], None] | None = None) -> None:
        ours()
        world = tree.world_transforms()
        for link in moved:
            rotation = np.ascontiguousarray(world[link][:3, :3].T, dtype=np.float32)
            offset = world[link][:3, 3].astype(np.float32)
            positions, turned = moved_positions[link], moved_normals[link]
            np.matmul(originals[link], rotation, out=positions)
            positions += offset
            np.matmul(normals[link], rotation, out=turned)
            if upload is not None:
                upload(link, positions)

    offscreen = OffscreenRenderer(ModelRenderer(model), 64, 64, samples=1)
    vbos = {link: offscreen.renderer.vertex_buffer(link) for link in moved}

    def upload(link: str, positions: npt.NDArray[np.float32]) -> None:
        # Positions only (normals would double it): a lower bound on the paper's upload.
        GL.glBindBuffer(GL.GL_ARRAY_BUFFER, vbos[link])
        GL.glBufferSubData(GL.GL_ARRAY_BUFFER, 0, positions.nbytes, positions)

    def baseline_upload() -> None:
        baseline(upload)
        GL.glFinish()

    try:
        ours_s = median_seconds(ours, 200, 0.5)
        cpu_s = median_seconds(baseline, 9, 1.0)
        upload_s = median_seconds(baseline_upload, 9, 1.0)
    finally:
        offscreen.close()
    return sum(len(v) for v in originals.values()), ours_s, cpu_s, upload_s


def bench_update() -> None:
    """Joint update cost, ours against the CPU vertex transform, as the model grows."""
    base = load_urdf()
    print(f"One '{JOINT}' update, median. ours = set the joint, recompute every link's")
    print("absolute matrix and build the frame's draw list; cpu = ours + transform the")
    print("moved links' vertices and normals on the CPU (numpy float32, the paper's way);")
    print("cpu+upload = cpu + glBufferSubData of the moved positions (OSMesa).")
    print()
    header = (
        f"{'vertices':>10} {'moved':>10} {'ours µs':>9} {'cpu µs':>10} {'cpu+upload µs':>14} "
        f"{'cpu/ours':>9}"
    )
    print(header)
    print("-" * len(header))
    results = []
    for split in UPDATE_SPLITS:
        model = subdivided_model(base, split)
        moved, ours_s, cpu_s, upload_s = measure_update(model)
        results.append(ours_s)
        print(
            f"{model.vertex_count:>10,} {moved:>10,} {ours_s * 1e6:>9.1f} "
            f"{cpu_s * 1e6:>10.1f} {upload_s * 1e6:>14.1f} {cpu_s / ours_s:>8.1f}x"
        )
    print()
    print(
        f"ours, largest / smallest model: {results[-1] / results[0]:.2f}x "
        "(target: within 1.5x, i.e. flat)"
    )


def write_subdivided_urdf(model: RobotModel, folder: Path) -> Path:
    """A copy of the shipped URDF whose meshes are the subdivided ones (binary STL)."""
    source = default_urdf_path()
    urdf = folder / source.name
    shutil.copy(source, urdf)
    (folder / "meshes").mkdir()
    record = np.dtype([("normal", "<f4", 3), ("vertices", "<f4", (3, 3)), ("attr", "<u2")])
    for link, mesh in model.meshes.items():
        data = np.zeros(mesh.triangle_count, dtype=record)
        data["normal"] = mesh.normals[::3]
        data["vertices"] = mesh.positions.reshape(-1, 3, 3)
        header = b"subdivided".ljust(80, b" ") + struct.pack("<I", mesh.triangle_count)
        (folder / "meshes" / f"{link}.stl").write_bytes(header + data.tobytes())
    return urdf


def frame_and_load(label: str, urdf: Path) -> None:
    """Load time (parse, upload) and median 800x600 frame time with and without MSAA."""
    started = time.perf_counter()
    model = load_urdf(urdf)
    parsed_s = time.perf_counter() - started
    width, height = FRAME_SIZE
    started = time.perf_counter()
    offscreen = OffscreenRenderer(ModelRenderer(model), width, height, samples=4)
    upload_s = time.perf_counter() - started
    uploaded_mb = sum(interleave(m).nbytes for m in model.meshes.values()) / 1e6
    tree = model.tree
    camera = OrbitCamera.framing(*model_bounds(model))
    angle = [0.0]

    def frame() -> npt.NDArray[np.uint8]:
        angle[0] += 0.01
        tree.set_position(JOINT, 0.8 + 0.5 * math.sin(angle[0]))
        return offscreen.render(build_frame(model, camera, width / height, live=tree))

    frame()  # shaders compiled, caches warm
    msaa_s = median_seconds(frame, 5, 2.0)
    offscreen.samples = 1
    offscreen.render(build_frame(model, camera, width / height, live=tree))
    plain_s = median_seconds(frame, 5, 2.0)
    offscreen.close()
    print(
        f"{label:<28} {model.triangle_count:>10,} {parsed_s * 1e3:>9.0f} "
        f"{upload_s * 1e3:>9.0f} {uploaded_mb:>7.1f} {plain_s * 1e3:>9.1f} {msaa_s * 1e3:>9.1f}"
    )


def bench_frame() -> None:
    """Frame and load times under OSMesa."""
    print(f"OSMesa, {os.cpu_count()} cores, {FRAME_SIZE[0]}x{FRAME_SIZE[1]}; median frame =")
    print("render + read back. load = URDF + meshes read and flat-shaded; upload = context,")
    print("shaders and the one-time vertex buffer upload.")
    print()
    header = (
        f"{'model':<28} {'triangles':>10} {'load ms':>9} {'upload ms':>9} {'GPU MB':>7} "
        f"{'frame ms':>9} {'4xMSAA ms':>9}"
    )
    print(header)
    print("-" * len(header))
    frame_and_load("shipped Engineer", default_urdf_path())
    heavy = subdivided_model(load_urdf(), FRAME_SPLIT_FOR_1M_TRIANGLES)
    with tempfile.TemporaryDirectory(prefix="ocu-bench-") as folder:
        urdf = write_subdivided_urdf(heavy, Path(folder))
        frame_and_load(f"subdivided x{FRAME_SPLIT_FOR_1M_TRIANGLES**2}", urdf)


def main() -> None:
    """Run the chosen benchmarks."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("which", nargs="?", choices=("update", "frame", "all"), default="all")
    args = parser.parse_args()
    if args.which in ("update", "all"):
        bench_update()
        print()
    if args.which in ("frame", "all"):
        bench_frame()


if __name__ == "__main__":
    main()
