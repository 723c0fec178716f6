"""research/studies/crash_anatomy.py: plateau.py's per-seed outputs gathered into one table and one figure."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from research.tests.studies import load_study


def _module():
    return load_study("crash_anatomy")


def _plateau_folder(root, seed, crashes):
    """A folder as research/studies/plateau.py writes it: the summary, and one row per collision of both hosts."""
    folder = root / str(seed)
    folder.mkdir()
    kinds = ("host_into_leader", "follower_into_host", "host_lane_change", "other_lane_change")
    learned = {f"collision/{k}": sum(c[0] == k for c in crashes) / 4 for k in kinds}
    learned.update({"collisions": len(crashes) / 4, "dangerous/tailgating": 3.0, "avg_speed_kmh": 50.0,
                    "episode_return": 200.0})
    (folder / "plateau_summary.json").write_text(json.dumps({"learned": learned}))
    rows = [dict(kind=k, host_speed_kmh=60.0, partner_speed_kmh=45.0, gap_m=0.8, host_action="LANE_RIGHT",
                 host_at_v_min=False, partner_connected=hgm, partner_in_camera=camera, host="learned")
            for k, hgm, camera in crashes]
    # The reference host's crashes are in the same file and must not count.
    rows.append(dict(kind="host_into_leader", host_speed_kmh=50.0, partner_speed_kmh=40.0, gap_m=1.0,
                     host_action="ACCELERATE", host_at_v_min=False, partner_connected=False, partner_in_camera=False,
                     host="idm"))
    pd.DataFrame(rows).to_csv(folder / "plateau_collisions.csv", index=False)
    return folder


def test_each_crash_partner_is_counted_by_what_showed_it(tmp_path):
    anatomy = _module()
    a = _plateau_folder(tmp_path, 100, [("host_lane_change", False, True), ("host_lane_change", True, True),
                                        ("host_lane_change", False, False), ("host_into_leader", True, False)])
    b = _plateau_folder(tmp_path, 101, [])
    out = tmp_path / "out"
    anatomy.main([str(a), str(b), "--out", str(out)])
    rates = pd.read_csv(out / "crash_anatomy.csv")
    first, second = rates.iloc[0], rates.iloc[1]
    assert (first["partner_seen_by_HGM_and_camera"], first["partner_seen_by_camera_only"],
            first["partner_seen_by_HGM_only"], first["partner_seen_by_neither"]) == (1, 1, 1, 1)
    assert first["collisions_per_episode"] == 1.0 and first["collisions_host_lane_change"] == 0.75
    assert second["collisions_per_episode"] == 0 and second["partner_seen_by_camera_only"] == 0
    assert (out / "crash_anatomy.png").stat().st_size > 0


def test_a_folder_without_plateau_output_is_named(tmp_path, capsys):
    with pytest.raises(SystemExit) as stop:
        _module().main([str(tmp_path / "103")])
    assert stop.value.code == 2
    err = capsys.readouterr().err
    assert "103" in err and "research/studies/plateau.py" in err
