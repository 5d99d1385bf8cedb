"""Parameter protocol client with PX4's bytewise encoding.

PX4 carries integer parameters bit for bit inside PARAM_VALUE's float field (an INT32 of 1
arrives as 1.4e-45 when read as a float), so values are encoded and decoded by param_type.
"""

from __future__ import annotations

import asyncio
import math
import struct
from collections.abc import Callable, Sequence
from dataclasses import dataclass

from pymavlink.dialects.v20 import development as mavlink

MAV_PARAM_TYPE_UINT8 = 1
MAV_PARAM_TYPE_INT8 = 2
MAV_PARAM_TYPE_UINT16 = 3
MAV_PARAM_TYPE_INT16 = 4
MAV_PARAM_TYPE_UINT32 = 5
MAV_PARAM_TYPE_INT32 = 6
MAV_PARAM_TYPE_REAL32 = 9

# struct format of each integer type within the 4 payload bytes (little endian)
_INT_FORMATS = {
    MAV_PARAM_TYPE_UINT8: "<B",
    MAV_PARAM_TYPE_INT8: "<b",
    MAV_PARAM_TYPE_UINT16: "<H",
    MAV_PARAM_TYPE_INT16: "<h",
    MAV_PARAM_TYPE_UINT32: "<I",
    MAV_PARAM_TYPE_INT32: "<i",
}
PARAM_ID_LEN = 16


class ParamError(Exception):
    """The vehicle refused a parameter value or answered with another one."""


def decode_param_value(raw: float, param_type: int) -> float | int:
    """A PARAM_VALUE's float field as the value it carries."""
    fmt = _INT_FORMATS.get(param_type)
    if fmt is None:
        return float(struct.unpack("<f", struct.pack("<f", raw))[0])
    payload = struct.pack("<f", raw)
    return int(struct.unpack(fmt, payload[: struct.calcsize(fmt)])[0])


def encode_param_value(value: float | int, param_type: int) -> float:
    """The float to put in PARAM_SET so the vehicle reads ``value`` of ``param_type``."""
    fmt = _INT_FORMATS.get(param_type)
    if fmt is None:
        return float(value)
    if float(value) != int(value):
        raise ParamError(f"{value!r} is not an integer")
    payload = struct.pack(fmt, int(value)).ljust(4, b"\0")
    return float(struct.unpack("<f", payload)[0])


def same_value(a: float | int, b: float | int, param_type: int) -> bool:
    if param_type in _INT_FORMATS:
        return int(a) == int(b)
    f32 = struct.Struct("<f")
    a32 = f32.unpack(f32.pack(float(a)))[0]
    b32 = f32.unpack(f32.pack(float(b)))[0]
    return bool(a32 == b32 or (math.isnan(a32) and math.isnan(b32)))


@dataclass(frozen=True)
class ParamEntry:
    value: float | int
    param_type: int
    index: int
    count: int


class ParamClient:
    """get / get many / get all / set, for one component, with a cache of what it said."""

    def __init__(
        self,
        *,
        send: Callable[[mavlink.MAVLink_message], None],
        mav: mavlink.MAVLink,
        target_system: int,
        target_component: int,
        timeout_s: float = 0.5,
        retries: int = 3,
        list_quiet_s: float = 0.5,
        list_rounds: int = 5,
    ) -> None:
        self._send = send
        self._mav = mav
        self._target = (target_system, target_component)
        self.timeout_s = timeout_s
        self.retries = retries
        self.list_quiet_s = list_quiet_s
        self.list_rounds = list_rounds
        self.cache: dict[str, ParamEntry] = {}
        self._by_index: dict[int, str] = {}
        self._count: int | None = None
        self._changed = asyncio.Event()
        self._set_lock = asyncio.Lock()

    def handle_param_value(self, msg: mavlink.MAVLink_param_value_message) -> None:
        name = _param_name(msg.param_id)
        entry = ParamEntry(
            decode_param_value(msg.param_value, msg.param_type),
            msg.param_type,
            msg.param_index,
            msg.param_count,
        )
        self.cache[name] = entry
        if 0 <= msg.param_index < 0xFFFF:
            self._by_index[msg.param_index] = name
        self._count = msg.param_count
        self._changed.set()

    async def _wait_change(self, timeout_s: float) -> bool:
        self._changed.clear()
        try:
            await asyncio.wait_for(self._changed.wait(), timeout_s)
        except TimeoutError:
            return False
        return True

    async def _request_until(self, request: Callable[[], None], done: Callable[[], bool]) -> bool:
        """Send ``request`` up to 1 + retries times until ``done()``."""
        loop = asyncio.get_running_loop()
        for _ in range(self.retries + 1):
            request()
            deadline = loop.time() + self.timeout_s
            while not done():
                remaining = deadline - loop.time()
                if remaining <= 0:
                    break
                await self._wait_change(remaining)
            if done():
                return True
        return False

    async def get(self, name: str) -> float | int:
        """Read one parameter. TimeoutError when the vehicle stays silent: PX4 never answers
        for a name it does not know."""
        wire_name = name.encode("ascii")[:PARAM_ID_LEN]
        self.cache.pop(name, None)

        def request() -> None:
            self._send(self._mav.param_request_read_encode(*self._target, wire_name, -1))

        if not await self._request_until(request, lambda: name in self.cache):
            raise TimeoutError(f"no answer for parameter {name}")
        return self.cache[name].value

    async def get_many(self, names: Sequence[str]) -> dict[str, float | int]:
        values = await asyncio.gather(*(self.get(n) for n in names))
        return dict(zip(names, values, strict=True))

    async def get_all(self) -> dict[str, float | int]:
        """PARAM_REQUEST_LIST, then PARAM_REQUEST_READ by index for whatever went missing."""
        self._by_index.clear()
        self._count = None
        self._send(self._mav.param_request_list_encode(*self._target))
        got_any = False
        for _ in range(self.retries + 1):
            if await self._wait_change(self.timeout_s):
                got_any = True
                break
            self._send(self._mav.param_request_list_encode(*self._target))
        if not got_any:
            raise TimeoutError("no answer to PARAM_REQUEST_LIST")
        for _ in range(self.list_rounds):
            while await self._wait_change(self.list_quiet_s):
                if self._missing() == []:
                    break
            missing = self._missing()
            if not missing:
                return {name: self.cache[name].value for name in self._by_index.values()}
            for index in missing:
                self._send(self._mav.param_request_read_encode(*self._target, b"", index))
        raise TimeoutError(
            f"parameters still missing after {self.list_rounds} rounds: "
            f"{len(self._missing())} of {self._count}"
        )

    def _missing(self) -> list[int]:
        if self._count is None:
            return []
        return [i for i in range(self._count) if i not in self._by_index]

    async def set(self, name: str, value: float | int) -> float | int:
        """PARAM_SET, then the PARAM_VALUE echo must carry the same value."""
        async with self._set_lock:
            entry = self.cache.get(name)
            if entry is None:
                await self.get(name)
                entry = self.cache[name]
            param_type = entry.param_type
            wire = encode_param_value(value, param_type)
            wire_name = name.encode("ascii")[:PARAM_ID_LEN]
            self.cache.pop(name, None)

            def request() -> None:
                self._send(self._mav.param_set_encode(*self._target, wire_name, wire, param_type))

            if not await self._request_until(request, lambda: name in self.cache):
                raise TimeoutError(f"no echo for parameter {name}")
            echoed = self.cache[name].value
            if not same_value(echoed, value, param_type):
                raise ParamError(f"{name}: asked for {value!r}, vehicle kept {echoed!r}")
            return echoed


def _param_name(param_id: str | bytes) -> str:
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", "replace")
    return param_id.rstrip("\0")
