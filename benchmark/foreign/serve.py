"""A foreign robot on pseudo-terminals: the project's pty server, given a foreign world."""
from __future__ import annotations

import signal
import sys
import threading
from pathlib import Path

from khepera_noise_ros.reality.emulator import Emulator

from .robot import ForeignWorld


def serve(params: dict, robots: int = 1, seed: int | None = None, link: str | None = None,
          condition: str = 'task') -> int:
    """Print one device per copy of the robot, then answer the Khepera serial protocol
    (with the emulator's ``Z`` extension) on each until Ctrl-C or SIGTERM."""
    world = ForeignWorld(params, robots, seed)
    world.set_condition(condition)
    stop = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: stop.set())
    with Emulator(world) as emulator:
        links = [Path(f'{link}{i}') for i in range(robots)] if link else []
        for path, port in zip(links, emulator.ports):
            path.unlink(missing_ok=True)
            path.symlink_to(port)
        print('\n'.join(emulator.ports), flush=True)
        print(f'foreign robot {params["name"]}: {robots} copies on ptys; Ctrl-C to stop',
              file=sys.stderr, flush=True)
        try:
            while not stop.wait(0.2):
                pass
        except KeyboardInterrupt:
            pass
        finally:
            for path in links:
                path.unlink(missing_ok=True)
    return 0
