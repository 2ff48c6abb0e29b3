"""Clock offsets on KinHEC's temporal track: the cross-correlation against the refined estimate.

Each sequence is exported as CSV by ``kinhec export`` and read by cpc2urdf's stream reader (the
path ``cpc2urdf handeye SEQ_robot.csv`` takes); the true offset comes from the sequence's
ground-truth file, which cpc2urdf never reads. Needs kinhec and a generated data set::

    python tests/kinhec_offsets.py /work/kinhec/data_small [--limit N]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import tempfile
from pathlib import Path

import numpy as np

from cpc2urdf.identification.handeye.stream_files import load_handeye_streams


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("data")
    ap.add_argument("--limit", type=int, default=None)
    args = ap.parse_args()
    import kinhec.io

    manifest = kinhec.io.load_manifest(args.data)
    ids = manifest[manifest.track == "temporal"].sequence_id.tolist()[: args.limit]
    coarse, refined, z = [], [], []
    with tempfile.TemporaryDirectory() as tmp:
        for seq in ids:
            cmd = ["kinhec", "export", args.data, seq, "--format", "csv", "--out", tmp]
            subprocess.run(cmd, check=True, capture_output=True)
            truth = json.loads((Path(tmp) / f"{seq}_groundtruth.json").read_text())["time_offset_s"]
            p = load_handeye_streams(Path(tmp) / f"{seq}_robot.csv").pairing
            assert p is not None and p.coarse is not None and p.sigma is not None
            coarse.append(p.coarse - truth)
            refined.append(p.time_offset - truth)
            z.append(refined[-1] / p.sigma)
            print(
                f"{seq}: true {truth * 1e3:6.1f} ms, error cross-correlation "
                f"{coarse[-1] * 1e3:+7.3f} ms, refined {refined[-1] * 1e3:+7.3f} ± "
                f"{p.sigma * 1e3:.3f} ms"
            )
    c, r, zz = (np.array(v) for v in (coarse, refined, z))
    print(
        f"{len(ids)} sequences: RMS error cross-correlation {np.sqrt(np.mean(c**2)) * 1e3:.3f} ms, "
        f"refined {np.sqrt(np.mean(r**2)) * 1e3:.3f} ms; median |error| "
        f"{np.median(abs(c)) * 1e3:.3f} / {np.median(abs(r)) * 1e3:.3f} ms; refined within 2 "
        f"sigma {np.mean(abs(zz) < 2):.0%}, RMS error/sigma {np.sqrt(np.mean(zz**2)):.2f}"
    )


if __name__ == "__main__":
    main()
