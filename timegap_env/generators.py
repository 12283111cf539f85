"""NumPy generators for many seeds at once: ``generators(seeds)[i]`` draws exactly what
``np.random.default_rng(seeds[i])`` draws.

``np.random.default_rng(seed)`` hashes the seed with a :class:`numpy.random.SeedSequence` and seeds a PCG64 with four
64-bit words the sequence generates; most of its cost is that sequence's set-up, paid per generator in Python. A
batched reset makes two generators an env (its own and its leader's), so here the hashing (NumPy's published
SeedSequence algorithm, on 32-bit words) runs on all the seeds at once, column by column, and each PCG64 takes its
four words from :class:`SeedWords`. Seeds that are not non-negative ints (None, bools, arrays, a SeedSequence) go
to ``default_rng`` itself.
"""

from __future__ import annotations

import secrets
from collections.abc import Sequence
from typing import Any

import numpy as np
from numpy.random.bit_generator import ISpawnableSeedSequence

from timegap_env.compiled import collection_paused

POOL_SIZE = 4  # SeedSequence's pool of 32-bit words (its default)
STATE_WORDS = 4  # 64-bit words a PCG64 is seeded with
ENTROPY_BITS = 128  # what SeedSequence() draws from the OS for an unseeded generator
HASHED_FROM = 32  # fewer int seeds than this go to default_rng one by one: hashing in arrays costs a hundred-odd
# NumPy calls whatever the number of seeds (make bench times both ways at this many seeds)
# SeedSequence's hash constants
INIT_A, MULT_A, INIT_B, MULT_B = 0x43B0D7E5, 0x931E8875, 0x8B51F9DD, 0x58F38DED
MIX_MULT_L, MIX_MULT_R, XSHIFT = 0xCA01F9DD, 0x4973F715, np.uint32(16)
WORD = 0xFFFFFFFF


class SeedWords(ISpawnableSeedSequence):
    """The four 64-bit words that ``SeedSequence(entropy).generate_state(4, np.uint64)`` gives, worked out
    beforehand: what a PCG64 asks its seed sequence for. Anything else (other words, ``spawn``) is asked of a
    SeedSequence of ``entropy``, made the first time and kept (so that spawned children follow on as its would).
    It is not a SeedSequence itself: ``rng.bit_generator.seed_seq`` has ``entropy`` but not ``pool``, ``spawn_key``
    or ``n_children_spawned`` (:meth:`sequence` has them)."""

    __slots__ = ("entropy", "words", "_sequence")

    def __init__(self, entropy: int, words: np.ndarray) -> None:
        self.entropy = entropy  # the seed, as SeedSequence.entropy
        self.words = words  # (STATE_WORDS,) uint64
        self._sequence: np.random.SeedSequence | None = None

    def __getstate__(self) -> tuple[int, np.ndarray, np.random.SeedSequence | None]:
        return self.entropy, self.words, self._sequence  # for pickle's protocols 0 and 1 too (a class with slots)

    def __setstate__(self, state: tuple[int, np.ndarray, np.random.SeedSequence | None]) -> None:
        self.entropy, self.words, self._sequence = state

    def generate_state(self, n_words: int, dtype: Any = np.uint32) -> np.ndarray:
        """``SeedSequence(entropy).generate_state(n_words, dtype)``."""
        if n_words == STATE_WORDS and np.dtype(dtype) == np.uint64:
            return self.words.copy()
        return self.sequence().generate_state(n_words, dtype)

    def spawn(self, n_children: int) -> list[np.random.SeedSequence]:  # type: ignore[override]
        """``SeedSequence(entropy).spawn(n_children)``, the children numbered on from the ones spawned before
        (SeedSequences, where numpy's stubs would have them of this class)."""
        return self.sequence().spawn(n_children)

    def sequence(self) -> np.random.SeedSequence:
        """The SeedSequence these words are of."""
        if self._sequence is None:
            self._sequence = np.random.SeedSequence(self.entropy)
        return self._sequence


@collection_paused()
def generators(seeds: Sequence[Any]) -> list[np.random.Generator]:
    """``[np.random.default_rng(seed) for seed in seeds]``, the same draws, made faster for many int seeds."""
    hashed = [i for i, seed in enumerate(seeds) if _is_entropy(seed)]
    if len(hashed) < HASHED_FROM:
        return [np.random.default_rng(seed) for seed in seeds]
    entropy = [int(seeds[i]) for i in hashed]
    made: list[np.random.Generator | None] = [None] * len(seeds)
    for i, seed, row in zip(hashed, entropy, seed_words(entropy)):
        made[i] = np.random.Generator(np.random.PCG64(SeedWords(seed, row)))  # type: ignore[arg-type]  # numpy's
        # stubs name SeedSequence; PCG64 takes any ISeedSequence
    return [np.random.default_rng(seed) if rng is None else rng for seed, rng in zip(seeds, made)]


def unseeded_generators(n: int) -> list[np.random.Generator]:
    """``n`` generators as ``np.random.default_rng()`` makes them: each from 128 bits of the OS's entropy."""
    return generators([secrets.randbits(ENTROPY_BITS) for _ in range(n)])


def seed_words(seeds: Sequence[int]) -> np.ndarray:
    """``SeedSequence(seed).generate_state(4, np.uint64)`` of each of ``seeds`` (non-negative ints): (len(seeds), 4)
    uint64."""
    out = np.empty((len(seeds), STATE_WORDS), dtype=np.uint64)
    by_length: dict[int, list[int]] = {}  # 32-bit words in a seed -> the seeds' indices
    for i, seed in enumerate(seeds):
        by_length.setdefault(max(1, -(-seed.bit_length() // 32)), []).append(i)
    for length, rows in by_length.items():
        group = [seeds[i] for i in rows]
        out[rows] = _hashed([np.array([(seed >> (32 * k)) & WORD for seed in group], dtype=np.uint32)
                             for k in range(length)])
    return out


def _is_entropy(seed: Any) -> bool:
    """Whether ``seed`` is a non-negative int (not a bool), which SeedSequence hashes as its 32-bit words."""
    return bool(isinstance(seed, (int, np.integer)) and not isinstance(seed, (bool, np.bool_)) and seed >= 0)


def _hashed(entropy: list[np.ndarray]) -> np.ndarray:
    """SeedSequence's pool mixed from the seeds' 32-bit words ``entropy`` (a (n,) uint32 array per word, least
    significant first), then the STATE_WORDS 64-bit words it generates from it: (n, STATE_WORDS) uint64."""
    const = INIT_A  # the hash's multiplier, advanced at every hash (the same for every row)

    def hashmix(value: np.ndarray) -> np.ndarray:
        nonlocal const
        value = value ^ np.uint32(const)
        const = const * MULT_A & WORD
        value = value * np.uint32(const)
        return value ^ (value >> XSHIFT)

    def mix(x: np.ndarray, y: np.ndarray) -> np.ndarray:
        result: np.ndarray = np.uint32(MIX_MULT_L) * x - np.uint32(MIX_MULT_R) * y
        return result ^ (result >> XSHIFT)

    length, zero = len(entropy), np.zeros_like(entropy[0])
    pool = [hashmix(entropy[i] if i < length else zero) for i in range(POOL_SIZE)]
    for source in range(POOL_SIZE):
        for target in range(POOL_SIZE):
            if source != target:
                pool[target] = mix(pool[target], hashmix(pool[source]))
    for source in range(POOL_SIZE, length):
        for target in range(POOL_SIZE):
            pool[target] = mix(pool[target], hashmix(entropy[source]))
    const, state = INIT_B, []
    for i in range(2 * STATE_WORDS):  # generate_state's 32-bit words, then paired, low word first
        value = pool[i % POOL_SIZE] ^ np.uint32(const)
        const = const * MULT_B & WORD
        value = value * np.uint32(const)
        state.append((value ^ (value >> XSHIFT)).astype(np.uint64))
    return np.stack([state[2 * k] | (state[2 * k + 1] << np.uint64(32)) for k in range(STATE_WORDS)], axis=1)
