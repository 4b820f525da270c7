"""The OBJ files load in trimesh and as PyBullet collision shapes (convex compound for concave)."""

from __future__ import annotations

import json

import numpy as np
import pybullet as pb
import pytest

from meshgen.pipeline import DatasetSummary


@pytest.fixture
def client() -> object:
    cid = pb.connect(pb.DIRECT)
    yield cid
    pb.disconnect(cid)


def test_pybullet_collision_shapes(meshed: DatasetSummary, client: int) -> None:
    folder = next(p for p in sorted(meshed.out.iterdir()) if (p / "scene.json").is_file())
    scenes = [
        json.loads((p / "scene.json").read_text())
        for p in sorted(meshed.out.iterdir())
        if (p / "scene.json").is_file()
    ]
    objs = [(meshed.out / s["image"], o) for s in scenes for o in s["objects"]]
    concave = [(f, o) for f, o in objs if o["convex_path"]][:3]
    convex = [(f, o) for f, o in objs if not o["convex_path"]][:2]
    assert concave
    assert folder.is_dir()
    for folder, obj in concave + convex:
        for name in filter(None, (obj["mesh_path"], obj["convex_path"])):
            shape = pb.createCollisionShape(
                pb.GEOM_MESH, fileName=str(folder / name), physicsClientId=client
            )
            assert shape >= 0
            body = pb.createMultiBody(
                baseMass=obj["mass_kg"], baseCollisionShapeIndex=shape, physicsClientId=client
            )
            lo, hi = pb.getAABB(body, physicsClientId=client)
            half = obj["height_m"] / 2
            assert np.isclose(lo[2], -half, atol=5e-3)
            assert np.isclose(hi[2], half, atol=5e-3)
            extent = np.array(hi[:2]) - np.array(lo[:2])
            assert extent.max() >= 0.9 * obj["width_m"]
            if name == obj["convex_path"]:
                data = pb.getCollisionShapeData(body, -1, physicsClientId=client)
                assert len(data) == obj["n_convex_pieces"]
            pb.removeBody(body, physicsClientId=client)
