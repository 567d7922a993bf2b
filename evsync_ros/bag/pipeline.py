"""Work split over two processes: blocks of bytes made in a forked process (an input read, restamped
and built into records; messages read and decoded into event times), built straight into memory
both share, and used in order by the caller, which writes or bins them (docs/bags.md, "Speed").
``serial`` does the same in one process."""

from __future__ import annotations

import contextlib
import gc
import mmap
import os
import pickle
import signal
import threading
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import IO, Any, TypeVar

from evsync_ros.errors import BagError
from evsync_ros.lifetime import die_with_parent

__all__ = ['SLOT_BYTES', 'Block', 'Use', 'available', 'chosen', 'pipelined', 'serial']

T = TypeVar('T')
Use = Callable[[memoryview | bytes, Any], None]
"""``use(data, meta)``: a block's bytes and what its ``fill`` said of them, used (written, binned)."""
SLOT_BYTES = 16 << 20
"""A block up to this size is built in shared memory; a larger one is pickled."""
_SLOTS = 4


@dataclass(frozen=True)
class Block:
    """A block of bytes to be made: ``fill(out)`` writes them into ``out`` from its start and returns
    (size, meta): their size and what the user needs of them (picklable), or meta None, nothing
    written, when a fixed ``out`` (not a bytearray, which grows) is too small. ``fill`` must be
    called before the next block is asked for (it may read the reader's buffer)."""

    fill: Callable[[bytearray | memoryview], tuple[int, Any]]


def available(*, jobs: int = 1) -> bool:
    """Whether a pipeline can run here: ``fork`` exists, this process may use a second core while
    ``jobs`` processes like it run at once (two cores each), and no other thread runs (a forked
    child holds only the calling thread, and whatever lock another held stays held in it)."""
    if not hasattr(os, 'fork') or threading.active_count() != 1:
        return False
    cores = os.sched_getaffinity(0) if hasattr(os, 'sched_getaffinity') else range(os.cpu_count() or 1)
    return len(cores) >= 2 * jobs


def chosen(parallel: bool | None) -> bool:
    """Whether to pipeline, as a caller's ``parallel`` says: yes, no, or (None) where ``available``."""
    return available() if parallel is None else parallel


def serial(blocks: Iterator[Block], use: Use) -> None:
    """Every block of ``blocks`` made, in one buffer kept from block to block (its pages stay), and
    used, in order."""
    buffer = bytearray()
    for block in blocks:
        size, meta = block.fill(buffer)
        assert meta is not None  # a bytearray grows
        with memoryview(buffer) as whole, whole[:size] as data:
            use(data, meta)


def pipelined(blocks: Iterator[Block], use: Use, *, result: Callable[[], T], name: str) -> T:
    """``serial``, with ``blocks`` run and made in a forked child while this process uses each block
    as it arrives; returns ``result()`` as the child has it once ``blocks`` ends (the state the
    blocks' making changed, which this process never sees).

    Raises:
        what ``blocks`` raised in the child (pickled back; a BagError with its text when it cannot
        be), what ``use`` raised (the child then killed), or BagError when the child ends
        without finishing.
    """
    shared = mmap.mmap(-1, _SLOTS * SLOT_BYTES)
    data_r, data_w = os.pipe()
    free_r, free_w = os.pipe()
    frozen = gc.get_freeze_count() > 0  # a caller's own freeze stays
    gc.freeze()  # the child's collector leaves what was here before (a writer's finaliser would flush it)
    try:
        pid = os.fork()
    except OSError:  # no process to be had (memory, a process limit): all of it here, as ``serial``
        if not frozen:
            gc.unfreeze()
        for fd in (data_r, data_w, free_r, free_w):
            os.close(fd)
        shared.close()
        serial(blocks, use)
        return result()
    if pid == 0:  # pragma: no cover - the child's coverage is not collected; the parent checks its work
        os.close(data_r)
        os.close(free_w)
        _child(blocks, result, shared, os.fdopen(data_w, 'wb'), free_r)
    if not frozen:
        gc.unfreeze()
    os.close(data_w)
    os.close(free_r)
    finished = False
    try:
        os.write(free_w, bytes(range(_SLOTS)))
        with os.fdopen(data_r, 'rb') as stream:
            out = _used(stream, shared, free_w, use, name)
        finished = True
        return out
    finally:
        os.close(free_w)
        if not finished:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        os.waitpid(pid, 0)
        with contextlib.suppress(BufferError):  # a view of a slot kept by the error's traceback: freed with it
            shared.close()


def _used(stream: IO[bytes], shared: mmap.mmap, free_w: int, use: Use, name: str) -> Any:
    """The parent's loop: each block the child announces used, its slot handed back, until the
    child's result (returned) or error (raised)."""
    while True:
        try:
            kind, *body = pickle.load(stream)
        except Exception as exc:  # noqa: BLE001 - ended (EOFError) or cut short mid-message, whatever the class
            raise BagError(f'{name}: the process reading it ended before it finished (killed, or out of memory: '
                           f'{type(exc).__name__})') from None
        if kind == 'end':
            return body[0]
        if kind == 'error':
            raise body[0]
        slot, held, meta = body  # held: the block's size in the slot, or its bytes
        if slot < 0:
            use(held, meta)
            continue
        with memoryview(shared) as whole, whole[slot * SLOT_BYTES:slot * SLOT_BYTES + held] as data:
            use(data, meta)
        with contextlib.suppress(BrokenPipeError):  # the child has sent its last block and gone
            os.write(free_w, bytes([slot]))


def _child(blocks: Iterator[Block], result: Callable[[], Any], shared: mmap.mmap, out: IO[bytes],
           free_r: int) -> None:  # pragma: no cover - runs in the forked child
    """The child's loop (``_made``), then ``result()`` sent; an error sent instead. It never returns:
    it leaves with ``os._exit``, running none of the parent's cleanup (the output's removal among
    them)."""
    status = 1
    try:
        die_with_parent(signal.SIGKILL)  # killed with the parent, where Linux can
        try:
            if _made(blocks, shared, out, free_r):
                pickle.dump(('end', result()), out)
        except BaseException as exc:  # noqa: BLE001 - every error goes back to the parent
            try:
                pickle.dump(('error', exc), out)
            except Exception:  # noqa: BLE001 - an error that does not pickle goes back as its text
                pickle.dump(('error', BagError(f'{type(exc).__name__}: {exc}')), out)
        out.flush()
        status = 0
    finally:
        os._exit(status)


def _made(blocks: Iterator[Block], shared: mmap.mmap, out: IO[bytes], free_r: int) -> bool:  # pragma: no cover
    """Each block built into a free slot (its number read from ``free_r``: the parent has written
    what the slot held) and announced on ``out``; one too big for a slot built apart and sent
    whole. False when the parent has gone."""
    slot = -1  # a free slot in hand: none
    with memoryview(shared) as whole:
        for block in blocks:
            if slot < 0:
                free = os.read(free_r, 1)
                if not free:
                    return False
                slot = free[0]
            with whole[slot * SLOT_BYTES:(slot + 1) * SLOT_BYTES] as room:
                size, meta = block.fill(room)
            if meta is not None:
                message: tuple[Any, ...] = (slot, size, meta)
                slot = -1
            else:  # the slot stays in hand for the next block
                apart = bytearray()
                size, meta = block.fill(apart)
                message = (-1, bytes(apart[:size]), meta)
            pickle.dump(('block', *message), out)
            out.flush()
    return True
