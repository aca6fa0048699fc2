"""A bounded libFuzzer run of the firmware's line parser (ASan + UBSan)."""

import os
import re
import subprocess

import pytest
from fw_helpers import BUILD, FIRMWARE_DIR, make

from appliance.hw import protocol as P

FUZZ_SECONDS = int(os.environ.get("INKSLICE_FUZZ_SECONDS", "60"))


@pytest.mark.slow
def test_line_parser_survives_a_bounded_fuzz_run():
    """`make fuzz-smoke` (what `make firmware-test` runs), for INKSLICE_FUZZ_SECONDS, from the
    committed seeds in fuzz/seeds: lines that pass the CRC, so the fuzzer starts past the
    checksum wall."""
    seeds = sorted((FIRMWARE_DIR / "fuzz" / "seeds").iterdir())
    assert len(seeds) >= len(P.VERBS)
    for seed in seeds:  # each still a whole, sealed command of the protocol as it stands
        _, verb, *args = P.unseal(seed.read_bytes().strip()).split()
        assert verb in P.VERBS and len(args) == P.VERBS[verb].args, seed.name
    make("fuzz")
    r = subprocess.run(
        [
            "make",
            "-s",
            "-C",
            str(FIRMWARE_DIR),
            f"BUILD={BUILD}",
            "fuzz-smoke",
            f"FUZZ_SECONDS={FUZZ_SECONDS}",
        ],
        capture_output=True,
        text=True,
        timeout=FUZZ_SECONDS + 120,
    )
    out = r.stderr
    m = re.search(r"Done (\d+) runs in (\d+) second", out)
    print(out[-1500:])
    assert r.returncode == 0, out[-3000:]
    assert "ERROR: AddressSanitizer" not in out and "runtime error" not in out
    assert m, out[-2000:]
    runs = int(m.group(1))
    print(f"fuzzer: {runs} executions in {m.group(2)} s, no crash, no sanitizer report")
    assert runs > 10000
