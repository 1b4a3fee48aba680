"""NormalBlocks: normals drawn ahead in blocks are the values drawn one call at a time, and the
generator is left where those calls would have left it (sim/normal_blocks.py)."""

import numpy as np

from ardrone_nmpc.sim.normal_blocks import NormalBlocks


def _calls(seed, sizes):
    rng = np.random.default_rng(seed)
    return [rng.standard_normal(k) for k in sizes], rng


def test_blocks_are_the_per_call_draws_across_block_ends():
    sizes = [6, 7, 3, 2, 6, 1, 9] * 40
    expected, _ = _calls(7, sizes)
    blocks = NormalBlocks(np.random.default_rng(7), block=16)  # many block ends
    for k, want in zip(sizes, expected):
        got = blocks.take(k)
        assert got.tobytes() == want.tobytes()


def test_ensure_keeps_the_sequence():
    sizes = [3, 3, 3, 6, 7] * 30
    expected, _ = _calls(3, sizes)
    blocks = NormalBlocks(np.random.default_rng(3), block=20)
    for k, want in zip(sizes, expected):
        blocks.ensure(9)
        got = blocks.values[blocks.pos:blocks.pos + k].copy()
        blocks.pos += k
        assert got.tobytes() == want.tobytes()


def test_sync_leaves_the_generator_where_the_calls_would_have():
    sizes = [3] * 11
    _, rng_calls = _calls(11, sizes)
    after_calls = (rng_calls.uniform(-1.0, 1.0, 3), rng_calls.random(),
                   rng_calls.standard_normal(5))
    rng = np.random.default_rng(11)
    blocks = NormalBlocks(rng, block=64)
    for k in sizes:
        blocks.take(k)
    blocks.sync()  # another user of the generator next
    after = (rng.uniform(-1.0, 1.0, 3), rng.random(), blocks.take(5).copy())
    assert after[0].tobytes() == after_calls[0].tobytes()
    assert after[1] == after_calls[1]
    assert after[2].tobytes() == after_calls[2].tobytes()


def test_sync_before_any_draw_is_a_no_op():
    rng = np.random.default_rng(5)
    NormalBlocks(rng).sync()
    assert rng.standard_normal() == np.random.default_rng(5).standard_normal()


def test_sync_after_many_carried_blocks_and_a_refill_after_a_sync():
    """Blocks carried over many refills (each value drawn once), a sync in the middle of a
    block, then blocks again: the per-call values, and the generator where the calls left
    it."""
    sizes = [6, 7, 9, 3] * 50
    rng_calls = np.random.default_rng(21)
    expected = [rng_calls.standard_normal(k) for k in sizes[:100]]
    between = rng_calls.random()
    expected += [rng_calls.standard_normal(k) for k in sizes[100:]]
    after = rng_calls.random()
    rng = np.random.default_rng(21)
    blocks = NormalBlocks(rng, block=32)
    got = []
    for i, k in enumerate(sizes):
        if i == 100:
            blocks.sync()
            assert rng.random() == between
        blocks.ensure(9)
        got.append(blocks.values[blocks.pos:blocks.pos + k].copy())
        blocks.pos += k
    blocks.sync()
    assert rng.random() == after
    assert all(a.tobytes() == b.tobytes() for a, b in zip(got, expected))
