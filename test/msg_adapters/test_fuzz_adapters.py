"""Fuzzing every adapter (hypothesis): random, mutated, empty and absurd messages give a MessageError or
events with their oddities counted; never another exception, never a hang, never a crash.

Every message type and encoding goes through the three things the tools do with a message: decode
it (with and without x, y, polarity), restamp it alone, and restamp it within a stream (offline and
live). Streams of good and bad messages keep their decoder usable: a bad message leaves it as it was.
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from evsync_ros.bag.reader import BagReader
from evsync_ros.core.clock import ClockCorrection
from evsync_ros.errors import MessageError
from evsync_testing.fuzz import FUZZ, event_arrays, event_packets, mutated, no_hang, payloads
from evsync_testing.reference import ReferenceRetimer
from msg_adapters.definitions import DVS_EVENT_ARRAY, EVENT_PACKET, EVENT_TYPES, PROPHESEE_EVENT_ARRAY
from msg_adapters.event_array import encode_event_array, parse_event_array
from msg_adapters.event_packet import ENCODINGS, encode_event_packet, parse_event_packet
from msg_adapters.evt3 import Evt3Retimer
from msg_adapters.registry import Restamper, decoder_for, restamp

S = 1_000_000_000
TIME_LIMIT = 1 << 62
corrections = st.builds(ClockCorrection, offset_ns=st.integers(-(10**12), 10**12),
                        skew_ppm=st.one_of(st.just(0.0), st.floats(-500, 500)),
                        anchor_ns=st.integers(0, 2**31 * S))


def any_message(msgtype: str) -> st.SearchStrategy[bytes]:
    base = event_packets() if msgtype == EVENT_PACKET else event_arrays()
    return st.one_of(base, mutated(base), st.binary(max_size=512))


def check_events(events, xyp: bool) -> None:
    assert events.t.dtype == np.int64 and events.t.ndim == 1
    assert np.all(np.abs(events.t) < TIME_LIMIT), 'an event time outside what the estimators take'
    if xyp:
        assert events.x.size == events.y.size == events.p.size == events.t.size


def decode_or_error(decoder, raw: bytes, xyp: bool):
    try:
        _, events = decoder.decode(raw, xyp=xyp)
    except MessageError as exc:
        assert str(exc)  # says what is wrong
        return None
    check_events(events, xyp)
    return events


def restamp_or_error(fn, raw: bytes):
    try:
        return fn(raw)
    except MessageError:
        return None


@pytest.mark.parametrize('msgtype', EVENT_TYPES)
@FUZZ
@given(data=st.data(), xyp=st.booleans())
def test_one_message_decodes_or_is_refused(msgtype, data, xyp):
    raw = data.draw(any_message(msgtype))
    with no_hang():
        decode_or_error(decoder_for(msgtype), raw, xyp)


@pytest.mark.parametrize('msgtype', EVENT_TYPES)
@FUZZ
@given(data=st.data(), xyp=st.booleans())
def test_one_message_gives_its_trigger_edges_as_decode_gives_its_events(msgtype, data, xyp):
    raw = data.draw(any_message(msgtype))
    with no_hang():
        plain = decode_or_error(decoder_for(msgtype), raw, xyp)
        try:
            _, events, edges = decoder_for(msgtype).decode_edges(raw, xyp=xyp)
        except MessageError:
            assert plain is None  # refused alike
            return
    assert plain is not None
    np.testing.assert_array_equal(events.t, plain.t)
    assert edges.t.dtype == np.int64 and edges.t.size == edges.value.size == edges.channel.size
    assert set(edges.value.tolist()) <= {0, 1}
    assert np.all(np.abs(edges.t) < TIME_LIMIT)


@pytest.mark.parametrize('msgtype', EVENT_TYPES)
@FUZZ
@given(data=st.data(), correction=corrections)
def test_one_message_restamps_or_is_refused(msgtype, data, correction):
    raw = data.draw(any_message(msgtype))
    with no_hang():
        out = restamp_or_error(lambda r: restamp(r, msgtype, correction), raw)
    if out is not None:  # what comes out is a message of the same type
        parse = parse_event_packet if msgtype == EVENT_PACKET else parse_event_array
        parse(out)


@pytest.mark.parametrize('msgtype', EVENT_TYPES)
@FUZZ
@given(data=st.data(), correction=corrections)
def test_a_stream_of_good_and_bad_messages_keeps_going(msgtype, data, correction):
    """One decoder and both restampers over a stream: every message decodes or is refused, the
    anomalies are whole counts, and the restampers never fail on a message the decoder took."""
    if msgtype == EVENT_PACKET:
        encoding = data.draw(st.sampled_from(ENCODINGS))
        good = event_packets(encoding)
    else:
        good = event_arrays()
    stream = data.draw(st.lists(st.one_of(good, mutated(good)), min_size=1, max_size=8))
    decoder = decoder_for(msgtype)
    offline, live = Restamper(msgtype), Restamper(msgtype, live=True)
    with no_hang(20):
        for raw in stream:
            events = decode_or_error(decoder, raw, xyp=True)
            for restamper in (offline, live):
                out = restamp_or_error(lambda r, rs=restamper: rs.restamp(r, correction), raw)
                if events is not None and out is None:  # refused only for a time that leaves its field
                    with pytest.raises(MessageError, match='leaves|outside|range'):
                        restamper.restamp(raw, correction)
    for name, n in decoder.anomalies.items():
        assert isinstance(name, str) and isinstance(n, int) and n > 0


@pytest.mark.parametrize('encoding', ['evt3', 'libcaer_cmp'])
@FUZZ
@given(data=st.data(), skew=st.floats(-1000, 1000))
def test_word_payloads_decode_and_retime_whatever_the_words(encoding, data, skew):
    """The C word loops and the evt3 retimer on arbitrary words (every type code, odd lengths)."""
    payloads_ = data.draw(st.lists(payloads(encoding), min_size=1, max_size=6))
    decoder = decoder_for(EVENT_PACKET)
    retimer = Evt3Retimer(skew)
    with no_hang():
        for k, payload in enumerate(payloads_):
            raw = encode_event_packet(stamp_ns=1_700_000_000 * S + k * 10**7, frame_id='f', width=640, height=480,
                                      seq=k, time_base=0 if encoding == 'evt3' else 1_700_000_000 * S,
                                      encoding=encoding, payload=payload)
            decode_or_error(decoder, raw, xyp=True)
            if encoding == 'evt3':
                out = retimer.retime(payload)
                assert len(out) % 2 == len(payload) % 2


@FUZZ
@given(data=st.data(), skew=st.one_of(st.just(0.0), st.floats(-1000, 1000)),
       offset=st.integers(-(10**12), 10**12), in_anchor=st.integers(0, 2**31 * S), out_move=st.integers(-10**9, 10**9))
def test_the_c_retimer_writes_what_the_numpy_walk_writes(data, skew, offset, in_anchor, out_move):
    """Evt3Retimer's C walk against the numpy walk of the reference, word for word, message after
    message, both ways it shifts: by a skew, and by a live correction between two anchors."""
    stream = data.draw(st.lists(payloads('evt3'), min_size=1, max_size=6))
    c_skew, np_skew = Evt3Retimer(skew), ReferenceRetimer(skew)
    c_live, np_live = Evt3Retimer(0.0), ReferenceRetimer(0.0)
    correction = ClockCorrection(offset_ns=offset, skew_ppm=skew, anchor_ns=in_anchor)
    out_anchor = in_anchor + offset + out_move

    def live_shift(u):
        return (correction.apply(u * 1000 + in_anchor) - out_anchor + 500) // 1000 - u

    with no_hang():
        for payload in stream:
            assert c_skew.retime(payload) == np_skew.retime(payload)
            u0 = c_live.u0
            first = c_live.first_time(payload)
            assert c_live.u0 == u0  # asking moves nothing
            want = np_live.retime(payload, shift_us=live_shift)
            got = c_live.retime_to(payload, in_anchor_ns=in_anchor, offset_ns=offset, skew_ppm=skew,
                                   anchor_ns=in_anchor, out_anchor_ns=out_anchor)
            assert (payload if got is None else got) == want
            assert first is None or c_live.u0 is not None
            assert (c_skew.u0, c_live.u0) == (np_skew.u0, np_live.u0)


@pytest.mark.parametrize('encoding', ENCODINGS)
@FUZZ
@given(time_base=st.integers(0, 2**64 - 1), stamp=st.integers(-(2**31) * S, (2**31 - 1) * S))
def test_absurd_time_bases_and_stamps_are_refused_by_name(encoding, time_base, stamp):
    raw = encode_event_packet(stamp_ns=stamp, frame_id='f', width=640, height=480, seq=1, time_base=time_base,
                              encoding=encoding, payload=bytes(64))
    decode_or_error(decoder_for(EVENT_PACKET), raw, xyp=False)


def _real_messages(real_data) -> list[tuple[str, bytes]]:
    out = []
    for name in ('evt3_sqlite3', 'libcaer_cmp_mcap'):
        with BagReader(real_data / name) as reader:
            for conn, _, raw in reader.messages():
                if conn.msgtype == EVENT_PACKET:
                    out.append((conn.msgtype, bytes(raw)))
                if len(out) % 4 == 3:
                    break
    return out


@FUZZ
@given(data=st.data())
def test_real_recordings_mutated(real_data, data):
    """Mutations of real driver messages (metavision evt3, libcaer_driver libcaer_cmp)."""
    messages = _real_messages(real_data)
    msgtype, raw = data.draw(st.sampled_from(messages))
    bad = data.draw(mutated(st.just(raw)))
    with no_hang():
        decode_or_error(decoder_for(msgtype), bad, xyp=True)
        restamp_or_error(lambda r: Restamper(msgtype, live=True).restamp(r, ClockCorrection(offset_ns=12_345)), bad)


@pytest.mark.parametrize('msgtype', [DVS_EVENT_ARRAY, PROPHESEE_EVENT_ARRAY])
def test_an_array_declaring_four_billion_events_is_refused_without_allocating(msgtype):
    raw = bytearray(encode_event_array(stamp_ns=S, frame_id='f', width=1, height=1, t=np.array([S]),
                                       x=np.array([0]), y=np.array([0]), p=np.array([1])))
    first = parse_event_array(raw).first
    raw[first - 4:first] = b'\xff\xff\xff\xff'
    with pytest.raises(MessageError, match='4294967295 events declared'):
        decoder_for(msgtype).decode(bytes(raw))
