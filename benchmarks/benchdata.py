"""What several benchmarks share: a project filled with copies of one measured point, and a
process's resident memory."""

from __future__ import annotations

import numpy as np

from gsgeo.service import PointRecord, Projects


def store_copies(svc: Projects, pid: str, seed, n: int,
                 rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Replace the measured point ``seed`` (a stored PointRecord with a result) by ``n`` copies
    P1..Pn spread over 1 km (E, N within ±500 m drawn from ``rng``, codes lamp/tree/kerb),
    written in one transaction without solving: fast to build, what an export or a report
    reads. Returns the copies' offsets (dE, dN) in metres."""
    de, dn = rng.uniform(-500, 500, n), rng.uniform(-500, 500, n)
    with svc.store.transaction() as tx:
        tx.delete_point(pid, seed.id)
        for i in range(n):
            res = dict(seed.result)
            res.update(point_id=f"P{i + 1}", code=("lamp", "tree", "kerb")[i % 3],
                       easting=res["easting"] + de[i], northing=res["northing"] + dn[i],
                       lon=res["lon"] + de[i] / 69_400.0, lat=res["lat"] + dn[i] / 111_200.0)
            tx.insert_point(PointRecord(project_id=pid, id=f"P{i + 1}", rays=seed.rays,
                                        code=res["code"], result=res, solved_rev=0))
    return de, dn


def rss_mb(pid: int) -> float:
    """Resident memory of process ``pid`` in MB (/proc), NaN where it is not said."""
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")
