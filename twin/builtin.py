"""The built-in dataset: the procedural sample, meshed once and cached.

The demo, the benchmarks and the tests run on data the project makes itself, so they need nothing
outside the repository. The meshed sample is cached under ``$CDW_TWIN_CACHE`` (default
``~/.cache/cdw-twin``), keyed by the sample's parameters; a partial cache is never used (the
meshgen output folder is complete once it exists, it is written atomically).
"""

from __future__ import annotations

from pathlib import Path

from interfaces.cache import cache_root

__all__ = ["SAMPLE_IMAGES", "SAMPLE_SEED", "builtin_dataset", "cache_root"]

SAMPLE_IMAGES = 24
SAMPLE_SEED = 0


def builtin_dataset(
    root: Path | None = None,
    *,
    images: int = SAMPLE_IMAGES,
    seed: int = SAMPLE_SEED,
    dense: bool = False,
) -> Path:
    """Path of the meshed built-in sample, generating and meshing it on first use.

    ``dense`` packs 9 to 12 objects into each image (clutter; the 40-object benchmark).
    """
    from meshgen.export import OUTPUT_VERSION
    from meshgen.sample import SAMPLE_VERSION, write_sample

    per_image = (9, 12) if dense else (3, 7)
    # the generator's and meshgen's output versions are in the name: a cache of an older
    # generator or of an older meshgen output is not reused
    name = f"builtin-v{SAMPLE_VERSION}-m{OUTPUT_VERSION}-i{images}-s{seed}" + (
        "-dense" if dense else ""
    )
    base = (root or cache_root()) / name
    meshes = base / "meshes"
    if (meshes / "index.csv").is_file():
        return meshes
    from meshgen.config import MeshgenConfig
    from meshgen.pipeline import mesh_dataset

    sample = base / "sample"
    if not (sample / "data.yaml").is_file():
        write_sample(sample, images=images, seed=seed, objects_per_image=per_image)
    mesh_dataset(sample, meshes, MeshgenConfig(seed=seed))
    return meshes
