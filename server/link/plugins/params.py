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

from server.link.core.requests import Requester

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


class ParamUnknown(LookupError):
    """The vehicle has no parameter of this name: its whole list, read, does not hold it."""

    def __init__(self, name: str) -> None:
        super().__init__(f"the vehicle has no parameter {name}")
        self.name = name


@dataclass(frozen=True)
class ParamEntry:
    value: float | int
    param_type: int
    index: int
    count: int


class ParamClient:
    """get / get many / get all / set, for one component, with a cache of what it said."""

    timeout_s = 0.5  # per try; the number of retries is the requester's
    list_quiet_s = 0.5  # a list is complete, or has gaps, once it has been quiet this long
    list_rounds = 8  # of asking for the gaps by index in a row with no answer
    read_backs = 2  # reads after a set never echoed as asked, all with another value: refused
    # the longest wait for the answers still on their way to stop: a set that ends in 504 so
    # takes at most 2 + 2 x (3 + 4 x 1.5 + 3) = 26 s, within a client's 30 s
    drain_limit_s = 3.0
    read_back_try_s = 1.5  # per try of a read after a set never echoed: the vehicle is slow

    def __init__(
        self,
        requests: Requester,
        on_change: Callable[[str, float | int, float | int], None] | None = None,
    ) -> None:
        self._requests = requests
        # told (name, before, now) when the vehicle reports another value than it did before:
        # a set by this server, by another ground station or on the vehicle itself (PX4 sends
        # every changed parameter unasked)
        self._on_change = on_change
        self._last_values: dict[str, float | int] = {}
        self.cache: dict[str, ParamEntry] = {}
        self._by_index: dict[int, str] = {}
        self._count: int | None = None
        self._received = 0  # PARAM_VALUEs taken in, so a wait can tell a new one came
        self._heard: dict[str, int] = {}  # PARAM_VALUEs taken in, by name
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
        before = self._last_values.get(name)
        self._last_values[name] = entry.value
        if (
            self._on_change is not None
            and before is not None
            and before != entry.value
            and not (math.isnan(before) and math.isnan(entry.value))
        ):
            self._on_change(name, before, entry.value)
        if 0 <= msg.param_index < 0xFFFF:
            self._by_index[msg.param_index] = name
        self._count = msg.param_count
        self._received += 1
        self._heard[name] = self._heard.get(name, 0) + 1

    async def _wait_value(self, timeout_s: float) -> bool:
        """True when a PARAM_VALUE arrives within timeout_s."""
        seen = self._received
        return await self._requests.wait_until(lambda: self._received != seen, timeout_s)

    def _request_read(self, wire_name: bytes, index: int = -1) -> None:
        """PARAM_REQUEST_READ by name, or by index when one is given."""
        requests = self._requests
        requests.send(requests.mav.param_request_read_encode(*requests.target, wire_name, index))

    async def get(self, name: str) -> float | int:
        """Read one parameter. PX4 never answers for a name it does not know, so silence is
        told apart by the vehicle's whole list: ParamUnknown at once when the list read
        before lacks the name, or after the list is read; TimeoutError when the vehicle
        answers neither."""
        if self._lacks(name):
            raise ParamUnknown(name)
        wire_name = name.encode("ascii")[:PARAM_ID_LEN]
        self.cache.pop(name, None)

        if not await self._requests.until(
            lambda: self._request_read(wire_name), lambda: name in self.cache, self.timeout_s
        ):
            if not self._list_complete():
                try:
                    await self.get_all()
                except TimeoutError:
                    raise TimeoutError(
                        f"no answer for parameter {name}, nor to PARAM_REQUEST_LIST"
                    ) from None
            if self._lacks(name):
                raise ParamUnknown(name)
            raise TimeoutError(f"no answer for parameter {name}")
        return self.cache[name].value

    def _list_complete(self) -> bool:
        """Whether every parameter of the vehicle's list has been seen since it was asked."""
        return self._count is not None and not self._missing()

    def _lacks(self, name: str) -> bool:
        """True when the whole list is known and ``name`` is not in it."""
        return self._list_complete() and name not in self._by_index.values()

    async def reread(self) -> dict[str, float | int]:
        """A rebooted vehicle: forget what it said and read again what had been read."""
        names = sorted(self.cache)
        self.cache.clear()
        self._by_index.clear()
        self._count = None
        return await self.get_many(names) if names else {}

    async def get_many(self, names: Sequence[str]) -> dict[str, float | int]:
        values = await asyncio.gather(*(self.get(n) for n in names))
        return dict(zip(names, values, strict=True))

    async def get_all(self) -> dict[str, float | int]:
        """PARAM_REQUEST_LIST, then PARAM_REQUEST_READ by index for whatever went missing."""
        self._by_index.clear()
        self._count = None

        requests = self._requests

        def request() -> None:
            requests.send(requests.mav.param_request_list_encode(*requests.target))

        if not await requests.until(request, lambda: self._count is not None, self.timeout_s):
            raise TimeoutError("no answer to PARAM_REQUEST_LIST")
        # On a lossy link every round of reads by index brings some back: give up only after
        # list_rounds rounds in a row that brought nothing.
        fruitless = 0
        before = self._count or 0
        while fruitless < self.list_rounds:
            while await self._wait_value(self.list_quiet_s):
                if self._missing() == []:
                    break
            missing = self._missing()
            if not missing:
                return {name: self.cache[name].value for name in self._by_index.values()}
            fruitless = fruitless + 1 if len(missing) >= before else 0
            before = len(missing)
            for index in missing:
                self._request_read(b"", index)
        raise TimeoutError(
            f"parameters still missing after {self.list_rounds} rounds without an answer: "
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

            requests = self._requests

            def request() -> None:
                requests.send(
                    requests.mav.param_set_encode(*requests.target, wire_name, wire, param_type)
                )

            def echoed_as_asked() -> bool:
                entry = self.cache.get(name)
                return entry is not None and same_value(entry.value, value, param_type)

            # a PARAM_VALUE with another value may be an older one still on its way (a read's
            # answer, the list, the vehicle's own report of a change), not the echo: the set
            # is sent again until its value comes back
            if await requests.until(request, echoed_as_asked, self.timeout_s):
                return self.cache[name].value
            # No echo with the value asked. A busy vehicle may echo late, behind the answers
            # to requests made before the set (a list asked again and again by a server that
            # waited for it) that all carry the old value. The vehicle answers in order:
            # once they have come, a read tells what it has now. Two such reads with another
            # value are a refusal (it holds its own: a clamp, a type, another writer).
            answered: float | int | None = None
            for _ in range(self.read_backs):
                now = await self._read_back(name, wire_name)
                if now is None:
                    raise TimeoutError(
                        f"no echo for parameter {name} set to {value!r}, nor an answer to a "
                        "read after it")
                if same_value(now.value, value, param_type):
                    return now.value
                answered = now.value
            raise ParamError(f"{name}: asked for {value!r}, the vehicle answered {answered!r}")

    async def _drained(self) -> None:
        """Once no PARAM_VALUE has come for list_quiet_s (at most drain_limit_s): every answer
        still on its way has come."""
        loop = asyncio.get_running_loop()
        end = loop.time() + self.drain_limit_s
        while (left_s := end - loop.time()) > 0 and await self._wait_value(
            min(self.list_quiet_s, left_s)
        ):
            pass

    async def _read_back(self, name: str, wire_name: bytes) -> ParamEntry | None:
        """The vehicle's value now, or None when it answers no read: a read by name once
        every answer still on its way has come; the vehicle answers in order, so the last
        value heard once its answers stop is the answer to it or a newer one."""
        await self._drained()
        heard = self._heard.get(name, 0)
        if not await self._requests.until(
            lambda: self._request_read(wire_name),
            lambda: self._heard.get(name, 0) > heard,
            self.read_back_try_s,
        ):
            return None
        await self._drained()
        return self.cache.get(name)


def _param_name(param_id: str | bytes) -> str:
    if isinstance(param_id, bytes):
        param_id = param_id.decode("ascii", "replace")
    return param_id.rstrip("\0")
