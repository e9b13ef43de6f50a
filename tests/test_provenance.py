"""A run continued on a CPU of another vendor says so in its provenance."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from qdil import provenance


def test_every_start_names_its_cpu_vendor(tmp_path: Path) -> None:
    assert provenance.record_start(tmp_path, 0) is None
    (entry,) = json.loads((tmp_path / "provenance.json").read_text())
    assert entry["cpu_vendor"] == provenance.cpu_vendor() != ""


def test_a_run_resumed_on_another_vendor_says_it_is_not_reproducible_on_one_machine(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setattr(provenance, "cpu_vendor", _vendor("AuthenticAMD"))
    assert provenance.record_start(tmp_path, 0) is None
    assert provenance.record_start(tmp_path, 10) is None  # the same vendor again
    monkeypatch.setattr(provenance, "cpu_vendor", _vendor("GenuineIntel"))
    note = provenance.record_start(tmp_path, 20)
    assert note is not None and "not reproducible bit for bit on one machine" in note
    starts = json.loads((tmp_path / "provenance.json").read_text())
    assert [s.get("note") for s in starts] == [None, None, note]
    assert provenance.vendors(starts) == ["AuthenticAMD", "GenuineIntel"]
    assert provenance.record_start(tmp_path, 30) is None  # said once, where it changed


def test_entries_from_before_the_vendor_was_recorded_get_it_from_the_cpu_name() -> None:
    amd, intel = {"cpu": "AMD EPYC"}, {"cpu": "Intel(R) Xeon(R) Processor @ 2.50GHz"}
    assert provenance.vendors([amd, intel, amd]) == ["AuthenticAMD", "GenuineIntel"]
    assert provenance.mixed_vendors_note([amd, amd]) is None


def _vendor(name: str):
    real = provenance.cpu_vendor

    def vendor(entry=None):
        return name if entry is None else real(entry)

    return vendor
