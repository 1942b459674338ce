"""The flipped-byte recovery figure of issue 13, measured by hand (not a test: minutes).

Records a session log of about ten chunks (as `test_fuzz_logs` does), then flips one
byte at a time: every byte of every record head (opcode and length), and ``per_chunk``
seeded positions inside each chunk and between chunks (message indexes); prints, over
the flips in each chunk, the share of the log's messages `read_log` keeps (min, mean).

    PYTHONPATH=$PWD python tests/fuzz/flipped_byte_figure.py [PER_CHUNK]
"""

from __future__ import annotations

import random
import sys
import tempfile
from pathlib import Path

from test_fuzz_logs import chunk_spans, record_session

from hydrojet_bench.logs import read_log


def main(per_chunk: int) -> None:
    folder = Path(tempfile.mkdtemp())
    log = folder / "session.mcap"
    record_session(log)
    data = log.read_bytes()
    total = len(read_log(log).messages)
    spans = chunk_spans(log)
    rng = random.Random(0)
    damaged = folder / "damaged.mcap"
    everything = []
    for number, (start, end) in enumerate(spans):
        following = spans[number + 1][0] if number + 1 < len(spans) else end
        positions = sorted(set(range(start, start + 9)) | {rng.randrange(start, end) for _ in range(per_chunk)}
                           | {rng.randrange(end, following) for _ in range(per_chunk // 5) if following > end})
        kept = []
        for position in positions:
            flipped = bytearray(data)
            flipped[position] ^= 1 << rng.randrange(8)
            damaged.write_bytes(bytes(flipped))
            kept.append(len(read_log(damaged).messages) / total)
        everything += kept
        print(f"chunk {number}: {len(positions)} flips, kept min {min(kept):.1%} mean {sum(kept) / len(kept):.1%}")
    print(f"{len(spans)} chunks, {total} messages, {len(everything)} flips: kept min {min(everything):.1%}, "
          f"mean {sum(everything) / len(everything):.1%}")


if __name__ == "__main__":
    main(int(sys.argv[1]) if len(sys.argv) > 1 else 40)
