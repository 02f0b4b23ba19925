"""Firmware-in-the-loop: run the real firmware .elf in simavr through hexa_simavr (hexa_driver/firmware).

`SimavrBoard` starts the harness, exposes the board's UART as a pty (`.port`, a symlink when `link=` is given),
injects ADC voltages (`set_adc`) and collects servo pulse widths measured on the output pins (`pulses`).

    with SimavrBoard("uno") as uno:
        ServoLink(uno.port) ...; uno.wait_pulse(pin=2, width_us=1500)
"""
from __future__ import annotations

import os
import subprocess
import threading
import time
from dataclasses import dataclass
from pathlib import Path

FIRMWARE_DIR = Path(__file__).resolve().parents[3] / "hexa_driver" / "firmware"
BOARDS = {
    "uno": ("atmega328p", "build-uno/uno_servo.elf"),
    "mega": ("atmega2560", "build-mega/mega_current.elf"),
}
HARNESS = "build-harness/hexa_simavr"
SERVO_PINS = (2, 3, 4, 5, 6, 7)   # PORTD bits = Arduino D2..D7, servo 1..6


class FirmwareMissingError(RuntimeError):
    """The firmware or the harness is not built (run `make firmware`)."""


@dataclass(frozen=True)
class Pulse:
    pin: int           # PORTD bit
    width_us: float    # measured in simulated CPU cycles
    sim_time_us: float # simulated time of the falling edge
    host_time: float   # time.monotonic() when the harness reported it


def firmware_paths(board: str, firmware_dir: Path = FIRMWARE_DIR) -> tuple[str, Path, Path]:
    """(mcu, elf, harness) for "uno" or "mega".

    Raises:
        FirmwareMissingError: a file is missing, naming it and the command that builds it.
    """
    if board not in BOARDS:
        raise ValueError(f"board {board!r} is not one of {sorted(BOARDS)}")
    mcu, elf = BOARDS[board]
    elf_path, harness = firmware_dir / elf, firmware_dir / HARNESS
    for p in (elf_path, harness):
        if not p.is_file():
            raise FirmwareMissingError(f"{p} is missing: build it with `make firmware` (needs gcc-avr avr-libc "
                                       f"arduino-core-avr arduino-mk simavr libsimavr-dev libelf-dev pkg-config)")
    return mcu, elf_path, harness


class SimavrBoard:
    """One simulated board running its real firmware (context manager)."""

    def __init__(self, board: str, link: str | os.PathLike | None = None,
                 firmware_dir: Path = FIRMWARE_DIR) -> None:
        self.board = board
        self.mcu, self.elf, self.harness = firmware_paths(board, firmware_dir)
        self.link = str(link) if link is not None else None
        self.proc: subprocess.Popen | None = None
        self.pty = ""
        self.pulses: list[Pulse] = []
        self._cond = threading.Condition()
        self._reader: threading.Thread | None = None
        self.stderr_lines: list[str] = []

    @property
    def port(self) -> str:
        return self.link or self.pty

    def start(self, timeout: float = 10.0) -> "SimavrBoard":
        args = [str(self.harness), "-m", self.mcu]
        if self.link:
            args += ["-l", self.link]
        args.append(str(self.elf))
        self.proc = subprocess.Popen(args, stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                     text=True, bufsize=1)
        out, err_pipe = self.proc.stdout, self.proc.stderr
        assert out is not None and err_pipe is not None   # both PIPE above
        t_end = time.monotonic() + timeout
        while time.monotonic() < t_end:
            line = out.readline()
            if not line:
                err = err_pipe.read()
                raise RuntimeError(f"hexa_simavr exited before opening its pty: {err.strip()}")
            if line.startswith("PTY "):
                self.pty = line.split(None, 1)[1].strip()
                break
        else:
            raise RuntimeError("hexa_simavr did not report its pty in time")
        self._reader = threading.Thread(target=self._read_events, daemon=True)
        self._reader.start()
        threading.Thread(target=self._read_stderr, daemon=True).start()
        return self

    def stop(self) -> None:
        if self.proc is None:
            return
        try:
            if self.proc.poll() is None:
                try:
                    stdin = self.proc.stdin
                    assert stdin is not None   # PIPE in start()
                    stdin.write("QUIT\n")
                    stdin.flush()
                except (BrokenPipeError, OSError, ValueError):
                    pass
                try:
                    self.proc.wait(timeout=2)
                except subprocess.TimeoutExpired:
                    self.proc.kill()
                    self.proc.wait(timeout=2)
        finally:
            self.proc = None

    def __enter__(self) -> "SimavrBoard":
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _read_events(self) -> None:
        proc = self.proc
        assert proc is not None and proc.stdout is not None
        for line in proc.stdout:
            parts = line.split()
            if len(parts) == 4 and parts[0] == "PULSE":
                p = Pulse(int(parts[1]), float(parts[2]), float(parts[3]), time.monotonic())
                with self._cond:
                    self.pulses.append(p)
                    if len(self.pulses) > 20000:
                        del self.pulses[:10000]
                    self._cond.notify_all()

    def _read_stderr(self) -> None:
        proc = self.proc
        if proc is None or proc.stderr is None:
            return
        for line in proc.stderr:
            self.stderr_lines.append(line.rstrip())

    def set_adc(self, channel: int, volts: float) -> None:
        """Set analog input `channel` (A0 = 0) to `volts` (simavr: counts = mV * 1023 // 5000)."""
        if self.proc is None or self.proc.stdin is None:
            raise RuntimeError("simavr board not running")
        self.proc.stdin.write(f"ADC {int(channel)} {int(round(volts * 1000))}\n")
        self.proc.stdin.flush()

    def latest_widths(self) -> dict[int, float]:
        """Last measured pulse width (us) per pin."""
        with self._cond:
            out: dict[int, float] = {}
            for p in self.pulses:
                out[p.pin] = p.width_us
            return out

    def wait_pulse(self, pin: int, width_us: float, tol_us: float = 2.0, timeout: float = 3.0,
                   after: float = 0.0) -> Pulse | None:
        """First pulse on `pin` within `tol_us` of `width_us` reported after host time `after`, or None."""
        t_end = time.monotonic() + timeout
        with self._cond:
            while True:
                for p in self.pulses:
                    if p.pin == pin and p.host_time >= after and abs(p.width_us - width_us) <= tol_us:
                        return p
                remaining = t_end - time.monotonic()
                if remaining <= 0:
                    return None
                self._cond.wait(min(remaining, 0.05))


def simavr_counts(volts: float) -> int:
    """ADC counts simavr's ADC model returns for `volts` at AVcc = 5 V (mV * 1023 // 5000, clipped to 1023)."""
    return min(int(round(volts * 1000)) * 1023 // 5000, 1023)
