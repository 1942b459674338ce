"""The standalone pty server: announces its path, serves clients, closes valves at exit."""

from __future__ import annotations

import asyncio
import queue
import threading

from drivers.plant import StaticPlant
from drivers.transport import open_transport
from drivers.valve.protocol import Ack, Arm, FrameDecoder, SetAll, decode_message, encode_message
from drivers.valve.serve import serve


def test_serve_announces_path_serves_and_closes_valves_on_stop(run_async) -> None:
    plant = StaticPlant()
    stop = threading.Event()
    lines: queue.Queue[str] = queue.Queue()
    result: list = []
    thread = threading.Thread(
        target=lambda: result.append(serve(plant, 0.5, stop=stop, announce=lines.put)), daemon=True
    )
    thread.start()
    try:
        path = lines.get(timeout=5)

        async def main() -> None:
            # Raw frames, and no ALL_OFF before leaving, as a crashed host would: the
            # server's exit must close the valves itself.
            link = open_transport(path)
            await link.open()
            decoder = FrameDecoder()
            for seq, message in enumerate((Arm(), SetAll((250, 500, 750)))):
                await link.write(encode_message(seq, message))
                frames: list = []
                async with asyncio.timeout(2):
                    while not frames:
                        frames = decoder.feed(await link.read())
                assert isinstance(decode_message(frames[0]), Ack)
            await link.close()

        run_async(main)
        assert plant.valve_duties_permille == (250, 500, 750)
    finally:
        stop.set()
        thread.join(5)
    assert not thread.is_alive()
    assert plant.valve_duties_permille == (0, 0, 0)
    assert result and result[0].duties_permille == (0, 0, 0)
