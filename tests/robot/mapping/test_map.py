"""The map module: vector format, capacity, and CLEAR_MAP / VECTOR / GET_MAP over a ring."""

from __future__ import annotations

import pytest

from modules.map import Program as MapProgram
from modules.mapping.map_request import request_map
from modules.mapping.vectormap import (
    CAPACITY,
    MapFull,
    VectorStore,
    mm_to_cm,
    pack_vectors,
    unpack_vectors,
    vector_to_wire,
)
from tests.support.memring import MemoryRing, wait_for


def test_vector_format_is_eight_bytes_of_int16_centimetres():
    blob = pack_vectors([(1, -2, 32767, -32768)])
    assert len(blob) == 8
    assert blob == bytes([1, 0, 0xFE, 0xFF, 0xFF, 0x7F, 0x00, 0x80])
    assert unpack_vectors(blob) == [(1, -2, 32767, -32768)]
    assert vector_to_wire(1234.0, -5.0, 400_000.0, -15.0) == {"x1": 123, "y1": 0, "x2": 32767, "y2": -2}
    assert mm_to_cm(-400_000) == -32768
    with pytest.raises(ValueError, match="multiple of 8"):
        unpack_vectors(b"\0" * 7)


def test_store_holds_4096_vectors_in_32_kb_and_refuses_more_without_overwriting():
    store = VectorStore()
    assert store.capacity == CAPACITY == 4096
    assert store.data.nbytes == 32 * 1024
    for i in range(CAPACITY):
        store.add(i % 1000, 1, 2, 3)
    with pytest.raises(MapFull):
        store.add(9, 9, 9, 9)
    assert len(store) == CAPACITY and store.left == 0
    assert store.vectors()[-1] == ((CAPACITY - 1) % 1000, 1, 2, 3)
    assert len(store.to_bytes()) == 32 * 1024


@pytest.fixture
def ring():
    r = MemoryRing(ids=[10, 50, 60], bitrate=None)
    r.wait_rounds(5)
    mapper = r.by_name("map")
    mapper.start_program(MapProgram)
    wait_for(lambda: mapper.program is not None and hasattr(mapper.program, "store"), what="map program")
    yield r
    for node in r.nodes.values():
        node.stop_program()
    r.close()


def _send_vectors(node, vectors):
    for x1, y1, x2, y2 in vectors:
        assert node.deliver("map", "VECTOR", timeout=2.0, x1=x1, y1=y1, x2=x2, y2=y2)


def test_get_map_round_trip_over_the_ring(ring):
    copro, main = ring.by_name("copro"), ring.by_name("main")
    vectors = [(i, -i, 10 * i, 300 - i) for i in range(40)]
    _send_vectors(copro, vectors)
    program = ring.by_name("map").program
    wait_for(lambda: program.store.count == 40, what="40 stored vectors")
    main.set_own_input_id()
    assert request_map(main, timeout=3.0) == vectors
    main_data = main.subscribe("map.data")
    wait_for(lambda: main_data["vector_count"] == 40, what="map.data vector_count")
    assert main_data["capacity_left"] == CAPACITY - 40

    assert main.deliver("map", "CLEAR_MAP", timeout=2.0)
    wait_for(lambda: program.store.count == 0, what="cleared map")
    assert request_map(main, timeout=3.0) == []
    wait_for(lambda: program.report()["maps_sent"] == 2, what="two maps sent")


@pytest.mark.slow
def test_full_map_answers_map_full_to_the_sender_and_overwrites_nothing(ring):
    program = ring.by_name("map").program
    for i in range(CAPACITY - 1):  # fill it directly: 4095 deliveries over the ring would be slow
        program.store.add(i % 100, 0, 0, 0)
    copro = ring.by_name("copro")
    copro.set_own_input_id()
    _send_vectors(copro, [(7, 7, 7, 7)])  # the last free slot
    wait_for(lambda: program.store.count == CAPACITY, what="the last slot filled")
    _send_vectors(copro, [(8, 8, 8, 8)])  # one too many
    error = copro.receive_command(timeout=3.0)
    assert error is not None and error.name == "ERROR"
    protocol = copro.protocol
    assert error.args == {
        "error": protocol.enums["error_code"]["MAP_FULL"],
        "about": protocol.common_commands["VECTOR"].code,
    }
    assert error.sender == 60
    assert program.store.count == CAPACITY
    assert program.store.vectors()[-1] == (7, 7, 7, 7)
    assert program.report()["refused_full"] == 1
