"""Statements per second of tmmaster.tmscript on a robot program's poll loop.

The loop reads two holding registers and an int32 from a fake Modbus host and compares
them, as a Script Project polling a PLC would. Run:

    .venv/bin/python benchmarks/bench_tmscript.py
"""

from __future__ import annotations

import time
from collections.abc import Sequence

from tmmaster.tmscript import ExecState, Execution, ModbusDevice, NullHost, parse

SCRIPT = """
define
{
  ModbusTCP plc = "127.0.0.1", 502
}
main
{
  int count = 0
  int hits = 0
  while (count < 20000)
  {
    int[] words = modbus_read_int16("plc", 1, "RO", 9000, 2)
    int[] big = modbus_read_int32("plc", 1, "RO", 9002, 2)
    if (words[0] == 1 && words[1] > 10 || big[0] == 65538)
    {
      hits += 1
    }
    count++
  }
  Display(hits)
}
"""


class _Plc(NullHost):
    def modbus_request(
        self,
        device: ModbusDevice,
        function: int,
        address: int,
        count: int,
        values: Sequence[int] | None,
    ) -> list[int]:
        return [1, 2, 3, 4][:count]


def main() -> None:
    """Run the loop to its end and print statements per second."""
    program = parse(SCRIPT)
    shown: list[str] = []
    execution = Execution(program, _Plc(on_display=shown.append))
    start = time.perf_counter()
    while execution.step(1000).state == ExecState.RUNNING:
        pass
    elapsed = time.perf_counter() - start
    # Each iteration: the loop test, 2 declarations, the if, hits += 1, count++ (6).
    counted = 20000 * 6
    print(f"{counted / elapsed:,.0f} statements/s ({elapsed:.3f} s, result {shown})")


if __name__ == "__main__":
    main()
