"""The MAVLink parameter protocol, vehicle side, and the NAK that answers MAVLink-FTP.

Replies are returned, not sent: the ground station sends them (`mission_protocol` works the
same way). Values travel as REAL32; a refused PARAM_SET is answered with the value in force.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from autopilot.params import ORDER, SPECS, ParamStore
from simbridge.hil import mavlink as mav

REAL32 = mav.MAV_PARAM_TYPE_REAL32


@dataclass(frozen=True)
class ParamOutcome:
    replies: tuple[Any, ...] = ()
    refused: str | None = None  # why a request was refused (a STATUSTEXT)
    # the refusal's kind, explained once per kind and while: every misspelt name is one kind
    refusal_kind: str = ""
    changed: str | None = None  # "NAME = value" when a parameter changed
    invalid: bool = False  # a request naming nothing there is (counted)


def param_value(store: ParamStore, name: str) -> Any:
    return mav.MAVLink_param_value_message(
        name.encode(), store.values[name], REAL32, len(ORDER), ORDER.index(name)
    )


def param_name(raw: Any) -> str:
    if isinstance(raw, bytes):
        raw = raw.decode("ascii", "replace")
    return str(raw).split("\x00", 1)[0]


def handle_param(store: ParamStore, m: Any) -> ParamOutcome:
    kind = m.get_type()
    if kind == "PARAM_REQUEST_LIST":
        return ParamOutcome(tuple(param_value(store, name) for name in ORDER))
    if kind == "PARAM_REQUEST_READ":
        name = param_name(m.param_id)
        if m.param_index >= 0:
            if m.param_index >= len(ORDER):
                return ParamOutcome(invalid=True)
            name = ORDER[m.param_index]
        if name not in SPECS:
            return ParamOutcome(invalid=True)
        return ParamOutcome((param_value(store, name),))
    if kind == "PARAM_SET":
        name = param_name(m.param_id)
        if name not in SPECS:
            why = f"unknown parameter {name}"
            return ParamOutcome(refused=why, refusal_kind="unknown parameter", invalid=True)
        why = store.set(name, float(m.param_value))
        reply = (param_value(store, name),)  # the value in force, new or old
        if why is not None:
            return ParamOutcome(reply, refused=why, refusal_kind=why)
        return ParamOutcome(reply, changed=f"parameter {name} = {store.values[name]:g}")
    return ParamOutcome()


def ftp_nak(m: Any) -> Any:
    """MAVLink-FTP is not offered: a NAK (opcode 129) with error FileNotFound (10), so
    MAVProxy falls back to the parameter protocol at once. MAVProxy routes a reply by its
    session and takes it as the answer when its sequence number is the request's + 1."""
    request = bytes(m.payload)
    payload = bytearray(251)
    seq = int.from_bytes(request[0:2], "little") if len(request) > 1 else 0
    payload[0:2] = ((seq + 1) & 0xFFFF).to_bytes(2, "little")
    payload[2] = request[2] if len(request) > 2 else 0  # session
    payload[3] = 129  # NAK
    payload[4] = 1  # size: one byte of error code
    payload[5] = request[3] if len(request) > 3 else 0  # opcode being answered
    payload[12] = 10  # FileNotFound
    return mav.MAVLink_file_transfer_protocol_message(
        0, m.get_srcSystem(), m.get_srcComponent(), list(payload)
    )
