"""The chain's topology: which oscillators the coupling springs eta_c join (a
`Graph`: a ring, eq. (5) of the paper, an open line, a 2-D lattice or any list of
links). The coupling force of the springs is in `forces`; a random stiffness
mistuning is in `mistuning`."""

import functools

import equinox as eqx
import numpy as np

from .._checks import check_count
from .._errors import ValidationError

#: The boundaries of a line of oscillators (`Graph.line`):
#: - "ring": eq. (5) of the paper, oscillator N coupled to oscillator 1 (n_osc links;
#:   link n joins oscillators n and n+1, link N joins N and 1);
#: - "free": an open line, the end oscillators coupled to one neighbour (n_osc - 1
#:   links; link n joins n and n+1);
#: - "fixed": an open line whose ends are also tied to the ground by eta_c
#:   (n_osc + 1 links; link 0 joins the ground and oscillator 1, link N oscillator
#:   N and the ground).
BOUNDARIES = ("ring", "free", "fixed")

#: The boundaries of each direction of a 2-D lattice (`Graph.lattice`); "ring" is
#: read as "periodic".
LATTICE_BOUNDARIES = ("free", "fixed", "periodic")

#: The end of a link that is the ground (displacement 0).
GROUND = -1


class Graph(eqx.Module):
    """The coupling springs of a chain as a graph: a list of links (left, right),
    0-based oscillator indices or `GROUND`, one spring eta_l each (`ChainParams.eta_c`,
    shape () or (n_links,), in this order). A spring's extension is x_right - x_left;
    it pulls each end toward the other. A ground link ties one oscillator to the
    ground (the fixed ends of a line).

    Make one with a constructor: `Graph.line` (the paper's ring, or an open line),
    `Graph.lattice` (a 2-D array, oscillator r * cols + c at row r, column c),
    `Graph.from_links` or `Graph.from_matrix`.

    **Fields** (static):

    - `n_osc`: number of oscillators.
    - `links`: tuple of (left, right) index pairs.
    - `kind`: "ring", "free" or "fixed" (a line of `BOUNDARIES`), "lattice" or "links".
    - `shape`: (n_osc,) for a line or a list of links, (rows, cols) for a lattice.
    - `boundary`: the boundary of each direction of `shape`, a tuple of names.
    """

    n_osc: int = eqx.field(static=True)
    links: tuple = eqx.field(static=True)
    kind: str = eqx.field(static=True)
    shape: tuple = eqx.field(static=True)
    boundary: tuple = eqx.field(static=True)

    def __check_init__(self):
        for left, right in self.links:
            for end in (left, right):
                if not (end == GROUND or 0 <= end < self.n_osc):
                    raise ValidationError(
                        f"link ({left}, {right}) names oscillator {end}, which does not "
                        f"exist: oscillators are 0..{self.n_osc - 1}, the ground {GROUND}")

    @classmethod
    def line(cls, n_osc: int, boundary: str = "ring") -> "Graph":
        """A line of `n_osc` oscillators with the links of `BOUNDARIES`, in that order.

        **Raises:** `ValidationError` for n_osc < 1 or an unknown boundary."""
        _check_size("n_osc", n_osc)
        if boundary not in BOUNDARIES:
            raise ValidationError(f"boundary must be one of {', '.join(BOUNDARIES)}, "
                                  f"got {boundary!r}")
        kind = {"ring": "periodic"}.get(boundary, boundary)
        return cls(n_osc=n_osc, links=tuple(_line_links(n_osc, kind)), kind=boundary,
                   shape=(n_osc,), boundary=(boundary,))

    @classmethod
    def lattice(cls, rows: int, cols: int, boundary: str | tuple[str, str] = "free"
                ) -> "Graph":
        """A 2-D lattice of rows x cols oscillators, each coupled to up to four
        neighbours (the sectors of a brake pad's lining, Fig. 1 of the paper);
        oscillator r * cols + c is row r, column c (row-major). Links: those along
        each row (r, c) - (r, c + 1) first, row by row, then those along each column
        (r, c) - (r + 1, c), column by column; each direction is a line of
        `LATTICE_BOUNDARIES` (free, fixed: ground links at both ends, periodic).

        **Arguments:**

        - `rows`, `cols`: the lattice's size (>= 1).
        - `boundary`: one name for both directions, or (across rows, along rows):
            the first applies to the columns' lines (top and bottom rows), the
            second to the rows' lines (left and right columns).

        **Raises:** `ValidationError` for a size < 1 or an unknown boundary."""
        _check_size("rows", rows)
        _check_size("cols", cols)
        names = (boundary, boundary) if isinstance(boundary, str) else tuple(boundary)
        names = tuple({"ring": "periodic"}.get(b, b) for b in names)
        if len(names) != 2 or any(b not in LATTICE_BOUNDARIES for b in names):
            raise ValidationError(f"lattice boundary must be one of "
                                  f"{', '.join(LATTICE_BOUNDARIES)} or a pair of them, "
                                  f"got {boundary!r}")
        index = np.arange(rows * cols).reshape(rows, cols)
        links = [_map(link, index[r]) for r in range(rows)
                 for link in _line_links(cols, names[1])]
        links += [_map(link, index[:, c]) for c in range(cols)
                  for link in _line_links(rows, names[0])]
        return cls(n_osc=rows * cols, links=tuple(links), kind="lattice",
                   shape=(rows, cols), boundary=names)

    @classmethod
    def from_links(cls, n_osc: int, links) -> "Graph":
        """Any graph: `links` a sequence of (left, right) pairs of 0-based oscillator
        indices, or `GROUND` (-1) for a spring to the ground.

        **Raises:** `ValidationError` for a link that is not a pair of integers or that
        names an oscillator that does not exist."""
        _check_size("n_osc", n_osc)
        pairs = []
        for link in links:
            try:
                left, right = (int(e) for e in link)
                if any(float(e) != int(e) for e in link):
                    raise ValueError
            except (TypeError, ValueError):
                raise ValidationError(f"a link must be a pair of integer oscillator "
                                      f"indices, got {link!r}") from None
            pairs.append((left, right))
        return cls(n_osc=n_osc, links=tuple(pairs), kind="links", shape=(n_osc,),
                   boundary=("links",))

    @classmethod
    def from_matrix(cls, coupling) -> tuple["Graph", np.ndarray]:
        """The graph and link stiffnesses of a symmetric coupling stiffness matrix C
        (the coupling part of x'' = -K x ..., K = diag(k_n) + C): a link (i, j), i < j,
        of stiffness -C_ij wherever C_ij != 0, and a ground link (i, ground) of
        stiffness equal to row i's sum wherever that is not zero.

        **Returns:** (graph, eta_c), eta_c of shape (n_links,).

        **Raises:** `ValidationError` naming the entry for a matrix that is not square,
        not finite, not symmetric, has a positive off-diagonal entry (a negative link
        stiffness) or a negative row sum (a negative ground stiffness)."""
        c = np.asarray(coupling, dtype=float)
        if c.ndim != 2 or c.shape[0] != c.shape[1] or c.shape[0] < 1:
            raise ValidationError(f"the coupling matrix must be square, got shape {c.shape}")
        if not np.all(np.isfinite(c)):
            raise ValidationError("the coupling matrix has a value that is not finite")
        scale = max(float(np.max(np.abs(c))), 1.0)
        tol = 1e-12 * scale
        bad = np.argwhere(np.abs(c - c.T) > tol)
        if bad.size:
            i, j = bad[0]
            raise ValidationError(f"the coupling matrix is not symmetric: entry ({i}, {j}) "
                                  f"is {c[i, j]!r}, entry ({j}, {i}) is {c[j, i]!r}")
        off = c - np.diag(np.diag(c))
        positive = np.argwhere(off > tol)
        if positive.size:
            i, j = positive[0]
            raise ValidationError(f"the coupling matrix has a positive off-diagonal entry "
                                  f"({i}, {j}) = {c[i, j]!r}: a link of negative stiffness")
        sums = c.sum(axis=1)
        if np.any(sums < -tol):
            i = int(np.flatnonzero(sums < -tol)[0])
            raise ValidationError(f"row {i} of the coupling matrix sums to {sums[i]!r} < 0: "
                                  "a spring to the ground of negative stiffness")
        n = c.shape[0]
        links, eta = [], []
        for i in range(n):
            for j in range(i + 1, n):
                if off[i, j] < -tol:
                    links.append((i, j))
                    eta.append(-off[i, j])
        for i in range(n):
            if sums[i] > tol:
                links.append((i, GROUND))
                eta.append(sums[i])
        return cls.from_links(n, links), np.asarray(eta, dtype=float)

    @property
    def n_links(self) -> int:
        """The number of links."""
        return len(self.links)

    @property
    def is_line(self) -> bool:
        """Whether this is a line of `BOUNDARIES` (the paper's ring or an open line)."""
        return self.kind in BOUNDARIES

    def row_links(self) -> int:
        """The number of a lattice's links along its rows (they come first in
        `links`); 0 for another graph."""
        if self.kind != "lattice":
            return 0
        return self.shape[0] * len(_line_links(self.shape[1], self.boundary[1]))

    def incidence(self) -> np.ndarray:
        """The incidence matrix D, shape (n_links, n_osc): D @ x is the extension of
        each link, x_right - x_left (ground columns left out); D.T @ (eta D x) is
        the coupling force (`coupling_force`)."""
        return _incidence(self)

    def adjacency(self) -> np.ndarray:
        """Whether oscillators i and j share a link, shape (n_osc, n_osc), bool
        (ground links and links of an oscillator to itself left out)."""
        a = np.zeros((self.n_osc, self.n_osc), dtype=bool)
        for left, right in self.links:
            if GROUND not in (left, right) and left != right:
                a[left, right] = a[right, left] = True
        return a

    def degree(self) -> np.ndarray:
        """The number of distinct neighbouring oscillators of each, shape (n_osc,)."""
        return self.adjacency().sum(axis=1)

    def distances(self) -> np.ndarray:
        """The graph distance (number of links) between each pair of oscillators,
        shape (n_osc, n_osc); unreachable pairs get n_osc (more than any path)."""
        return _distances(self)

    def clusters(self, on: np.ndarray) -> np.ndarray:
        """The number of separate groups of linked oscillators among those marked
        `on`, shape (..., n_osc) -> (...)."""
        from scipy.sparse.csgraph import connected_components

        on = np.asarray(on, dtype=bool)
        adjacency = self.adjacency()
        out = np.zeros(on.shape[:-1], dtype=int)
        for index in np.ndindex(on.shape[:-1]):
            sites = np.flatnonzero(on[index])
            if sites.size:
                out[index] = connected_components(adjacency[np.ix_(sites, sites)],
                                                  directed=False)[0]
        return out

    def describe(self) -> str:
        """A short name: "ring", "free", "fixed", "lattice 4x5 free" or "20 links"."""
        if self.kind == "lattice":
            b = self.boundary[0] if self.boundary[0] == self.boundary[1] else ",".join(
                self.boundary)
            return f"lattice {self.shape[0]}x{self.shape[1]} {b}"
        return self.kind if self.is_line else f"{self.n_links} links"


def as_graph(boundary, n_osc: int) -> Graph:
    """A `Graph` as it is, or the line of `n_osc` oscillators with the boundary of
    that name (`BOUNDARIES`).

    **Raises:** `ValidationError` for an unknown boundary or a graph of another size."""
    if isinstance(boundary, Graph):
        if boundary.n_osc != n_osc:
            raise ValidationError(f"the graph has {boundary.n_osc} oscillators, not {n_osc}")
        return boundary
    return Graph.line(n_osc, boundary)


def require_line(params, what: str) -> None:
    """Refuse a chain that is not a line, for a study that is 1-D by nature (the
    transfer matrix of a line gives its localization factor).

    **Raises:** `ValidationError` naming the study and the graph."""
    if not params.graph.is_line:
        raise ValidationError(f"{what} is 1-D by nature (the transfer matrix of a line); "
                              f"the chain is a {params.graph.describe()}: give a line "
                              "(ring, free or fixed)")


def _check_size(name: str, value) -> None:
    check_count(name, value)


def _line_links(n: int, boundary: str) -> list[tuple[int, int]]:
    """The links of a line of n sites (0-based), for "periodic", "free" or "fixed"."""
    inner = [(i, i + 1) for i in range(n - 1)]
    if boundary == "periodic":
        return inner + [(n - 1, 0)]
    if boundary == "fixed":
        return [(GROUND, 0)] + inner + [(n - 1, GROUND)]
    return inner


def _map(link, index) -> tuple[int, int]:
    return tuple(GROUND if e == GROUND else int(index[e]) for e in link)


@functools.lru_cache(maxsize=64)
def _incidence(graph: Graph) -> np.ndarray:
    d = np.zeros((graph.n_links, graph.n_osc))
    for row, (left, right) in enumerate(graph.links):
        if right != GROUND:
            d[row, right] += 1.0
        if left != GROUND:
            d[row, left] -= 1.0
    return d


@functools.lru_cache(maxsize=64)
def _distances(graph: Graph) -> np.ndarray:
    from scipy.sparse.csgraph import shortest_path

    d = shortest_path(graph.adjacency().astype(float), unweighted=True)
    return np.where(np.isfinite(d), d, graph.n_osc).astype(int)


def n_links(boundary: str, n_osc: int) -> int:
    """The number of coupling springs of a line of `n_osc` oscillators.

    **Raises:**

    `ValidationError` for an unknown boundary.
    """
    return Graph.line(n_osc, boundary).n_links


def neighbours(boundary: str, n_osc: int) -> tuple[np.ndarray, np.ndarray]:
    """The left and the right neighbour of each oscillator of a line, 0-based
    indices of shape (n_osc,): on the ring oscillator N's right neighbour is
    oscillator 1 (a ring of one is its own neighbour); on an open line ("free",
    "fixed") the ends have none, -1.

    **Raises:**

    `ValidationError` for an unknown boundary.
    """
    n_links(boundary, n_osc)
    index = np.arange(n_osc)
    left, right = (index - 1) % n_osc, (index + 1) % n_osc
    if boundary != "ring":
        left[0], right[-1] = -1, -1
    return left, right
