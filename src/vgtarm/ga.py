"""Binary-coded genetic algorithm that minimises a vectorised cost.

This is the genetic algorithm of the paper's switching control method (Bayram, Section V-C
and Appendix B), written so that any cost can use it:

- every real gene is an ``n_bits``-bit code (most significant bit first) mapped linearly onto
  ``[lower_i, upper_i]``: code 0 gives ``lower_i`` exactly, code ``2**n_bits - 1`` gives
  ``upper_i`` exactly (:func:`decode`, :func:`encode`);
- population 50, at most 50 generations;
- stochastic universal sampling selection (:func:`stochastic_universal_sampling`);
- uniform crossover applied to each pair of parents with probability 0.6; a crossed pair swaps
  each bit position with probability 0.5 (:func:`uniform_crossover`);
- bit-flip mutation with probability 0.001 per bit (:func:`bit_flip_mutation`);
- elitism: the ``elite_count`` best individuals (default 1) go unchanged into the next
  generation, so the best individual found so far is never lost.

Choices the paper leaves open (it ran MATLAB and does not state them):

- **Cost, not fitness.** The cost is minimised (the paper minimises the Euclidean norm of the
  tracking error). Infinite costs (+inf and -inf: a candidate that cannot be used) rank worst
  and are never reported as the best unless no individual has a finite cost, in which case the
  result has ``success=False`` and its ``reason`` says so. A NaN cost is no cost: it is refused
  (:class:`~vgtarm.errors.InputError` naming the individual and the generation).
- **Rank scaling** as MATLAB's ``ga`` does by default (``fitscalingrank``): the individual of
  rank ``r`` (rank 1 = lowest cost) gets an expectation proportional to ``1/sqrt(r)``, scaled so
  the expectations sum to the number of parents to select (:func:`rank_expectations`). Unlike
  MATLAB, which breaks ties by sort order, tied costs share the mean of their rank weights, so
  identical individuals get identical expectations.
- **Generation layout.** Each generation keeps the ``elite_count`` best individuals and breeds
  ``population_size - elite_count`` children: that many parents are drawn by SUS from the whole
  population, shuffled, paired consecutively, crossed and mutated. Elites are not mutated.
- **Evaluation.** The cost is called once per generation with the children whose code differs
  from both of their parents' codes; unchanged children and the elites reuse their known cost.
  The cost is therefore assumed deterministic: with a noisy cost, the reported best cost is the
  sample drawn when that individual was first evaluated.

Randomness comes only from the ``seed`` argument: the same integer seed (or a generator in the
same state) gives the same result bit for bit. ``seed=None`` draws fresh entropy, so a run is
reproducible only when a seed is given.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike, NDArray

from . import checks
from .errors import InputError, VgtarmError, refuse_masked, shown

__all__ = [
    "MAX_SEED",
    "CostFunction",
    "GAOptions",
    "GAResult",
    "bit_flip_mutation",
    "check_seed",
    "decode",
    "encode",
    "minimize",
    "rank_expectations",
    "stochastic_universal_sampling",
    "uniform_crossover",
]

CostFunction = Callable[[NDArray[np.float64]], ArrayLike]
"""A vectorised cost: (m, n_genes) decoded candidates -> (m,) costs to minimise."""

_MAX_BITS = 32
#: Largest population and number of generations (far beyond the paper's 50 and 50; bounds that
#: keep a mistyped value from allocating the machine's memory or running for days).
_MAX_POPULATION = 1_000_000
_MAX_GENERATIONS = 1_000_000
#: Largest seed accepted wherever a seed enters vgtarm, 2**63 - 1 (:data:`vgtarm.checks.MAX_SEED`,
#: where every seed is checked: a run's seed is stored as a 64-bit signed integer).
MAX_SEED = checks.MAX_SEED


# ---------------------------------------------------------------------------------------------
# Validation helpers
# ---------------------------------------------------------------------------------------------


def check_seed(value: object, name: str, error: type[VgtarmError] = InputError) -> int:
    """``value`` as a seed: a whole number from 0 to :data:`MAX_SEED`, else one ``error`` line
    naming ``name``, showing the value and the accepted range (booleans are refused);
    :func:`vgtarm.checks.seed` under the name its callers know."""
    return checks.seed(name, value, error=error)


def _as_rng(seed: object, name: str = "seed") -> np.random.Generator:
    """Turn an integer seed (0 to :data:`MAX_SEED`), a generator or None into a
    :class:`numpy.random.Generator`."""
    if isinstance(seed, np.random.Generator):
        return seed
    if seed is None:
        return np.random.default_rng()
    return np.random.default_rng(checks.seed(name, seed, expected=f"{checks.SEED_RANGE}, a numpy Generator or None"))


def _check_bounds(lower: ArrayLike, upper: ArrayLike) -> tuple[NDArray[np.float64], ...]:
    """Validate gene bounds: 1-D, same non-zero length, finite, ``lower <= upper``."""
    lo = checks.finite_array("lower", lower, (None,))
    hi = checks.finite_array("upper", upper, (None,))
    if lo.size == 0:
        checks.refuse("lower", lower, "at least one gene's bound")
    if lo.shape != hi.shape:
        checks.refuse("upper.shape", hi.shape, f"{lo.shape}, the shape of lower")
    bad = np.flatnonzero(lo > hi)
    if bad.size:
        i = int(bad[0])
        checks.refuse(f"lower[{i}]", lo[i], f"at most upper[{i}] = {hi[i]!r}")
    if not np.all(np.isfinite(hi - lo)):
        raise InputError("`upper - lower` must be finite (bounds too far apart)")
    return lo, hi


def _check_bits(name: str, bits: ArrayLike) -> NDArray[np.uint8]:
    """Return ``bits`` as uint8 after checking every entry is 0 or 1."""
    arr = np.asarray(bits)
    if arr.dtype == np.bool_:
        return arr.astype(np.uint8)
    if arr.dtype.kind not in "iuf":
        checks.refuse(name, bits, "an array of 0 and 1")
    bad = np.argwhere((arr != 0) & (arr != 1))
    if bad.size:
        index = tuple(int(i) for i in bad[0])
        checks.refuse(f"{name}[{', '.join(map(str, index))}]" if index else name, arr[index], "0 or 1")
    return arr.astype(np.uint8, copy=False)


# ---------------------------------------------------------------------------------------------
# Options and result
# ---------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class GAOptions:
    """Settings of :func:`minimize`; the defaults are the paper's (Appendix B).

    Attributes:
        n_bits: bits per gene, 1 to 32 (paper: 8).
        population_size: individuals per generation, >= 2 (paper: 50).
        max_generations: generations after the initial population, >= 0 (paper: 50).
        crossover_probability: probability that a pair of parents is crossed, in [0, 1]
            (paper: 0.6).
        mutation_probability: probability that a child's bit is flipped, in [0, 1]
            (paper: 0.001).
        elite_count: best individuals copied unchanged into the next generation, 0 to
            ``population_size - 1`` (default 1: the paper keeps the best individual).
        stall_generations: stop early once the best cost has not improved for this many
            generations, >= 1; None runs all ``max_generations``.
    """

    n_bits: int = 8
    population_size: int = 50
    max_generations: int = 50
    crossover_probability: float = 0.6
    mutation_probability: float = 0.001
    elite_count: int = 1
    stall_generations: int | None = None

    def __post_init__(self) -> None:
        checks.whole("n_bits", self.n_bits, 1, _MAX_BITS)
        population = checks.whole("population_size", self.population_size, 2, _MAX_POPULATION)
        checks.whole("max_generations", self.max_generations, 0, _MAX_GENERATIONS)
        checks.probability("crossover_probability", self.crossover_probability)
        checks.probability("mutation_probability", self.mutation_probability)
        checks.whole("elite_count", self.elite_count, 0, population - 1)
        if self.stall_generations is not None:
            checks.whole("stall_generations", self.stall_generations, 1)


@dataclass(frozen=True)
class GAResult:
    """Outcome of :func:`minimize`.

    Attributes:
        x: (n_genes,) decoded values of the best individual found.
        cost: its cost (``inf`` when no individual had a finite cost).
        bits: (n_genes * n_bits,) uint8 code of the best individual, most significant bit first.
        generations: generations run after the initial population.
        n_evaluations: individuals passed to the cost function, in total.
        history: (generations + 1,) best cost found so far after each generation; index 0 is the
            initial population. Non-increasing.
        success: True when a finite cost was found.
        reason: why the run stopped.
    """

    x: NDArray[np.float64]
    cost: float
    bits: NDArray[np.uint8]
    generations: int
    n_evaluations: int
    history: NDArray[np.float64]
    success: bool
    reason: str


_DEFAULT_OPTIONS = GAOptions()


# ---------------------------------------------------------------------------------------------
# Coding
# ---------------------------------------------------------------------------------------------


def _weights(n_bits: int) -> NDArray[np.float64]:
    """(n_bits,) place values of an MSB-first code."""
    return np.ldexp(1.0, np.arange(n_bits - 1, -1, -1))


def _decode(
    bits: NDArray[np.uint8], lower: NDArray[np.float64], upper: NDArray[np.float64], n_bits: int
) -> NDArray[np.float64]:
    """Unchecked :func:`decode`."""
    n_genes = lower.shape[0]
    top = float(2**n_bits - 1)
    if n_bits == 8:  # the paper's coding: one byte per gene, packed by NumPy (same values, ~10x faster)
        codes = np.packbits(bits, axis=-1).astype(np.float64)
    else:
        codes = bits.reshape(*bits.shape[:-1], n_genes, n_bits) @ _weights(n_bits)
    fraction = codes / top
    values = np.minimum(lower + fraction * (upper - lower), upper)
    return np.where(fraction == 1.0, upper, values)


def decode(bits: ArrayLike, lower: ArrayLike, upper: ArrayLike, n_bits: int = 8) -> NDArray[np.float64]:
    """Map binary codes onto real genes.

    Gene ``i`` is the ``n_bits``-bit unsigned integer ``c`` read most significant bit first,
    mapped to ``lower[i] + c / (2**n_bits - 1) * (upper[i] - lower[i])``; code 0 gives
    ``lower[i]`` and the all-ones code gives ``upper[i]`` exactly, and the map is monotone.

    Args:
        bits: (..., n_genes * n_bits) array of 0 and 1.
        lower: (n_genes,) lower bounds.
        upper: (n_genes,) upper bounds, ``>= lower``.
        n_bits: bits per gene, 1 to 32.

    Returns:
        (..., n_genes) float64 gene values.
    """
    n_bits = checks.whole("n_bits", n_bits, 1, _MAX_BITS)
    lo, hi = _check_bounds(lower, upper)
    arr = _check_bits("bits", bits)
    expected = lo.shape[0] * n_bits
    if arr.ndim < 1 or arr.shape[-1] != expected:
        raise InputError(
            f"`bits` must have shape (..., {expected}) for {lo.shape[0]} genes of {n_bits} bits, got {arr.shape}"
        )
    return _decode(arr, lo, hi, n_bits)


def _encode(
    values: NDArray[np.float64],
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
    n_bits: int,
) -> NDArray[np.uint8]:
    """Unchecked :func:`encode`."""
    top = 2**n_bits - 1
    span = upper - lower
    safe_span = np.where(span > 0.0, span, 1.0)
    fraction = np.where(span > 0.0, (values - lower) / safe_span, 0.0)
    codes = np.clip(np.rint(fraction * top), 0, top).astype(np.int64)
    shifts = np.arange(n_bits - 1, -1, -1, dtype=np.int64)
    bits = ((codes[..., None] >> shifts) & 1).astype(np.uint8)
    return bits.reshape(*values.shape[:-1], values.shape[-1] * n_bits)


def encode(values: ArrayLike, lower: ArrayLike, upper: ArrayLike, n_bits: int = 8) -> NDArray[np.uint8]:
    """Code real genes as the nearest ``n_bits``-bit codes (inverse of :func:`decode`).

    Values outside ``[lower, upper]`` are clipped into range; a gene with ``lower == upper``
    gets code 0. ``decode(encode(v))`` is the grid value nearest to ``v`` and
    ``encode(decode(b)) == b``.

    Args:
        values: (..., n_genes) finite gene values.
        lower: (n_genes,) lower bounds.
        upper: (n_genes,) upper bounds, ``>= lower``.
        n_bits: bits per gene, 1 to 32.

    Returns:
        (..., n_genes * n_bits) uint8 array of 0 and 1, most significant bit first.
    """
    n_bits = checks.whole("n_bits", n_bits, 1, _MAX_BITS)
    lo, hi = _check_bounds(lower, upper)
    arr = checks.number_array("values", values)
    if arr.ndim < 1 or arr.shape[-1] != lo.shape[0]:
        raise InputError(f"`values` must have shape (..., {lo.shape[0]}), got {arr.shape}")
    return _encode(checks.finite_array("values", arr), lo, hi, n_bits)


# ---------------------------------------------------------------------------------------------
# Selection
# ---------------------------------------------------------------------------------------------


def rank_expectations(costs: ArrayLike, n: int) -> NDArray[np.float64]:
    """Expected number of copies of each individual under rank scaling (MATLAB fitscalingrank).

    Costs are ranked in ascending order (rank 1 = lowest cost); rank ``r`` has weight
    ``1/sqrt(r)``. Tied costs share the mean weight of their ranks. Non-finite costs (NaN, +inf,
    -inf) take the worst ranks, so they get the smallest expectations. The weights are scaled so
    that they sum to ``n``.

    Args:
        costs: (P,) costs to minimise, P >= 1.
        n: number of parents to select, >= 0.

    Returns:
        (P,) float64 expectations, non-negative, summing to ``n`` and non-increasing in cost.
    """
    n = checks.whole("n", n, 0)
    arr = np.asarray(costs, dtype=np.float64)
    if arr.ndim != 1 or arr.size == 0:
        raise InputError(f"`costs` must be a non-empty 1-D array, got shape {arr.shape}")
    return _rank_expectations(arr, n)


def _rank_expectations(costs: NDArray[np.float64], n: int) -> NDArray[np.float64]:
    """Unchecked :func:`rank_expectations`."""
    clean = np.where(np.isfinite(costs), costs, np.inf)
    order = np.argsort(clean, kind="stable")
    ranked = clean[order]
    weights = 1.0 / np.sqrt(np.arange(1, costs.size + 1, dtype=np.float64))
    starts = np.flatnonzero(np.r_[True, ranked[1:] != ranked[:-1]])
    counts = np.diff(np.r_[starts, costs.size])
    shared = np.repeat(np.add.reduceat(weights, starts) / counts, counts)
    expectations = np.empty_like(shared)
    expectations[order] = shared
    return expectations * (n / expectations.sum())


def stochastic_universal_sampling(
    expectations: ArrayLike, n: int, rng: np.random.Generator | int | None
) -> NDArray[np.intp]:
    """Select ``n`` individuals by stochastic universal sampling (Baker, 1987).

    The expectations are rescaled to sum to ``n`` and laid end to end on ``[0, n)``; ``n``
    pointers one unit apart, starting at a single uniform draw in ``[0, 1)``, pick the
    individuals they fall on. Individual ``i`` is therefore chosen ``floor(e_i)`` or
    ``ceil(e_i)`` times, where ``e_i`` is its rescaled expectation.

    Args:
        expectations: (P,) non-negative finite expectations with a positive sum.
        n: number of individuals to select, >= 0.
        rng: numpy Generator (advanced in place), integer seed, or None (fresh entropy).

    Returns:
        (n,) indices into the population in ascending order; shuffle them before pairing.
    """
    n = checks.whole("n", n, 0)
    arr = np.asarray(expectations, dtype=np.float64)
    if arr.ndim != 1 or arr.size == 0:
        raise InputError(f"`expectations` must be a non-empty 1-D array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)) or np.any(arr < 0.0) or not arr.sum() > 0.0:
        raise InputError("`expectations` must be finite, non-negative and have a positive sum")
    return _sus(arr, n, _as_rng(rng, "rng"))


def _sus(expectations: NDArray[np.float64], n: int, rng: np.random.Generator) -> NDArray[np.intp]:
    """Unchecked :func:`stochastic_universal_sampling`."""
    edges = np.cumsum(expectations)
    edges *= n / edges[-1]
    edges[-1] = n  # guard the last pointer against rounding
    pointers = rng.random() + np.arange(n, dtype=np.float64)
    return np.searchsorted(edges, pointers, side="right").astype(np.intp)


# ---------------------------------------------------------------------------------------------
# Variation
# ---------------------------------------------------------------------------------------------


def uniform_crossover(
    parents: ArrayLike, probability: float, rng: np.random.Generator | int | None
) -> NDArray[np.uint8]:
    """Uniform crossover of consecutive pairs of parents.

    Rows ``2k`` and ``2k + 1`` form a pair. With probability ``probability`` the pair is crossed:
    each bit position is swapped between the two children with probability 0.5. Otherwise the
    children are copies of the parents. With an odd number of rows the last one is copied.

    Args:
        parents: (P, L) array of 0 and 1.
        probability: probability that a pair is crossed, in [0, 1].
        rng: numpy Generator (advanced in place), integer seed, or None (fresh entropy).

    Returns:
        (P, L) uint8 children; the input is not modified.
    """
    probability = checks.probability("probability", probability)
    arr = _check_bits("parents", parents)
    if arr.ndim != 2:
        raise InputError(f"`parents` must be a 2-D array (P, L), got shape {arr.shape}")
    return _crossover(arr, probability, _as_rng(rng, "rng"))


def _random_bits(rng: np.random.Generator, rows: int, length: int) -> NDArray[np.uint8]:
    """(rows, length) independent fair bits, 8 per random byte."""
    raw = rng.integers(0, 256, size=(rows, -(-length // 8)), dtype=np.uint8)
    return np.unpackbits(raw, axis=1, count=length)


def _crossover(parents: NDArray[np.uint8], probability: float, rng: np.random.Generator) -> NDArray[np.uint8]:
    """Unchecked :func:`uniform_crossover`."""
    children = parents.copy()
    n_pairs = parents.shape[0] // 2
    if n_pairs == 0:
        return children
    crossed = rng.random(n_pairs) < probability
    rows = np.flatnonzero(crossed)
    if rows.size == 0:
        return children
    mask = _random_bits(rng, rows.size, parents.shape[1])
    first = 2 * rows
    second = first + 1
    swap = (parents[first] ^ parents[second]) & mask
    children[first] ^= swap
    children[second] ^= swap
    return children


def bit_flip_mutation(bits: ArrayLike, probability: float, rng: np.random.Generator | int | None) -> NDArray[np.uint8]:
    """Flip each bit independently with probability ``probability``.

    Args:
        bits: array of 0 and 1, any shape.
        probability: per-bit flip probability, in [0, 1].
        rng: numpy Generator (advanced in place), integer seed, or None (fresh entropy).

    Returns:
        uint8 array of the same shape; the input is not modified.
    """
    probability = checks.probability("probability", probability)
    arr = _check_bits("bits", bits)
    return _mutate(arr, probability, _as_rng(rng, "rng"))


def _mutate(bits: NDArray[np.uint8], probability: float, rng: np.random.Generator) -> NDArray[np.uint8]:
    """Unchecked :func:`bit_flip_mutation`.

    Draws the number of flips from Binomial(size, p) and then that many distinct positions
    uniformly, which is the same distribution as independent per-bit flips but far cheaper for
    small ``p``.
    """
    out = np.array(bits, dtype=np.uint8, copy=True)
    if out.size == 0 or probability == 0.0:
        return out
    n_flips = int(rng.binomial(out.size, probability))
    if n_flips:
        positions = rng.choice(out.size, size=n_flips, replace=False)
        flat = out.reshape(-1)
        flat[positions] ^= 1
    return out


# ---------------------------------------------------------------------------------------------
# Driver
# ---------------------------------------------------------------------------------------------


def _evaluate(
    cost: CostFunction, candidates: NDArray[np.float64], generation: int, individuals: NDArray[np.intp]
) -> NDArray[np.float64]:
    """Call ``cost`` on (m, n_genes) candidates, the ``individuals`` (their rows in the population)
    of ``generation`` (0: the initial population); check it returns (m,) numbers, none NaN, and
    rank the infinite ones worst (+inf)."""
    m = candidates.shape[0]
    returned = cost(candidates)
    refuse_masked(returned, "`cost`'s result")
    try:
        values = np.asarray(returned, dtype=np.float64)
    except (TypeError, ValueError, OverflowError):
        raise InputError(f"`cost` must return ({m},) numbers, got {shown(returned)}") from None
    if values.shape != (m,):
        raise InputError(
            f"`cost` must return an array of shape ({m},) for a ({m}, {candidates.shape[1]}) "
            f"population, got shape {values.shape}"
        )
    undefined = np.flatnonzero(np.isnan(values))
    if undefined.size:
        k = int(undefined[0])
        raise InputError(
            f"`cost` returned nan for individual {int(individuals[k])} of generation {generation} (genes "
            f"{shown(candidates[k].tolist(), 120)}; {undefined.size} of the {m} evaluated): expected a number "
            "(inf ranks a candidate worst)"
        )
    return np.where(np.isfinite(values), values, np.inf)


def _initial_population(
    initial: ArrayLike | None,
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
    options: GAOptions,
    rng: np.random.Generator,
) -> NDArray[np.uint8]:
    """(population_size, n_genes * n_bits) first population: seeded rows, then random bits."""
    n_genes = lower.shape[0]
    length = n_genes * options.n_bits
    if initial is None:
        seeded = np.empty((0, length), dtype=np.uint8)
    else:
        values = checks.number_array("initial", initial)
        if values.ndim == 1:
            values = values[None, :]
        if values.ndim != 2 or values.shape[1] != n_genes:
            raise InputError(f"`initial` must have shape (k, {n_genes}), got {np.shape(initial)}")
        if values.shape[0] > options.population_size:
            raise InputError(
                f"`initial` must have at most population_size={options.population_size} rows, got {values.shape[0]}"
            )
        seeded = _encode(checks.finite_array("initial", values), lower, upper, options.n_bits)
    n_random = options.population_size - seeded.shape[0]
    return np.concatenate([seeded, _random_bits(rng, n_random, length)])


def minimize(
    cost: CostFunction,
    lower: ArrayLike,
    upper: ArrayLike,
    *,
    options: GAOptions = _DEFAULT_OPTIONS,
    seed: int | np.random.Generator | None = None,
    initial: ArrayLike | None = None,
) -> GAResult:
    """Minimise ``cost`` over the box ``[lower, upper]`` with the binary-coded GA.

    Args:
        cost: vectorised cost; takes an (m, n_genes) float64 array of decoded candidates and
            returns (m,) costs. It is called once per generation with the new individuals
            only (m varies, m = population_size for the initial population); it must be
            deterministic. Non-finite costs rank worst.
        lower: (n_genes,) finite lower bounds.
        upper: (n_genes,) finite upper bounds, ``>= lower``.
        options: GA settings; the defaults are the paper's.
        seed: integer seed or numpy Generator (advanced in place). None draws fresh entropy, so
            pass a seed for a reproducible run.
        initial: optional (k, n_genes) values (or one (n_genes,) vector) that seed the first k
            individuals, encoded to the nearest code after clipping into range; the other
            individuals get uniform random bits.

    Returns:
        A :class:`GAResult` with the best individual found. Running out of generations or
        stalling is not an error; ``success`` is False only when no finite cost was found.
    """
    if not isinstance(options, GAOptions):
        raise InputError(f"`options` must be a GAOptions, got {type(options).__name__}")
    if not callable(cost):
        raise InputError(f"`cost` must be callable, got {type(cost).__name__}")
    lo, hi = _check_bounds(lower, upper)
    rng = _as_rng(seed)
    n_elite = options.elite_count

    population = _initial_population(initial, lo, hi, options, rng)
    costs = _evaluate(cost, _decode(population, lo, hi, options.n_bits), 0, np.arange(population.shape[0]))
    n_evaluations = population.shape[0]

    best_index = int(np.argmin(costs))
    best_bits = population[best_index].copy()
    best_cost = float(costs[best_index])
    history = [best_cost]
    mate = _mates(options.population_size - n_elite)

    generation = 0
    last_improvement = 0
    reason = f"reached max_generations={options.max_generations}"
    for generation in range(1, options.max_generations + 1):
        children, child_costs, evaluated = _offspring(cost, population, costs, mate, generation, lo, hi, options, rng)
        n_evaluations += evaluated

        elites = np.argsort(costs, kind="stable")[:n_elite]
        population = np.concatenate([population[elites], children])
        costs = np.concatenate([costs[elites], child_costs])

        index = int(np.argmin(costs))
        if costs[index] < best_cost:
            best_cost = float(costs[index])
            best_bits = population[index].copy()
            last_improvement = generation
        history.append(best_cost)

        stall = options.stall_generations
        if stall is not None and generation - last_improvement >= stall:
            reason = f"best cost did not improve for stall_generations={stall} generations"
            break

    return _result(best_bits, best_cost, (lo, hi), options.n_bits, generation, n_evaluations, history, reason)


def _mates(n_children: int) -> NDArray[np.intp]:
    """Each child's mate in the shuffled mating pool (the last one of an odd pool is its own)."""
    mate = np.arange(n_children) ^ 1
    if n_children % 2:
        mate[-1] = n_children - 1
    return mate


def _offspring(
    cost: CostFunction,
    population: NDArray[np.uint8],
    costs: NDArray[np.float64],
    mate: NDArray[np.intp],
    generation: int,
    lower: NDArray[np.float64],
    upper: NDArray[np.float64],
    options: GAOptions,
    rng: np.random.Generator,
) -> tuple[NDArray[np.uint8], NDArray[np.float64], int]:
    """The children of ``generation``: parents drawn by rank (stochastic universal sampling,
    shuffled into pairs), crossed and mutated; a child equal to one of its parents keeps that
    parent's cost, the others are evaluated. Returns the children, their costs and how many were
    evaluated."""
    n_children = options.population_size - options.elite_count
    expectations = _rank_expectations(costs, n_children)
    pool = rng.permutation(_sus(expectations, n_children, rng))
    parents = population[pool]
    parent_costs = costs[pool]
    crossed = _crossover(parents, float(options.crossover_probability), rng)
    children = _mutate(crossed, float(options.mutation_probability), rng)

    # Children equal to one of their parents keep that parent's cost.
    same_as_first = np.all(children == parents, axis=1)
    same_as_mate = np.all(children == parents[mate], axis=1)
    child_costs = np.where(same_as_first, parent_costs, parent_costs[mate])
    new = np.flatnonzero(~(same_as_first | same_as_mate))
    if new.size:
        decoded = _decode(children[new], lower, upper, options.n_bits)
        child_costs[new] = _evaluate(cost, decoded, generation, options.elite_count + new)
    return children, child_costs, int(new.size)


def _result(
    best_bits: NDArray[np.uint8],
    best_cost: float,
    bounds: tuple[NDArray[np.float64], NDArray[np.float64]],
    n_bits: int,
    generations: int,
    n_evaluations: int,
    history: list[float],
    reason: str,
) -> GAResult:
    """The record of a search that found ``best_bits`` (read-only arrays); without a finite cost
    it failed, and ``reason`` says so."""
    success = bool(np.isfinite(best_cost))
    if not success:
        reason = f"no individual had a finite cost ({reason})"
    x = _decode(best_bits, *bounds, n_bits)
    history_array = np.asarray(history, dtype=np.float64)
    for arr in (x, best_bits, history_array):
        arr.setflags(write=False)
    return GAResult(
        x=x,
        cost=best_cost,
        bits=best_bits,
        generations=generations,
        n_evaluations=n_evaluations,
        history=history_array,
        success=success,
        reason=reason,
    )
