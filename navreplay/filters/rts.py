"""The backward pass of the Rauch-Tung-Striebel fixed-interval smoother, in the error-state
form that closed-loop (feedback) filters need; pure math, no I/O.

The forward filter stores, at every epoch k it outputs (docs/smoothing.md):

    P_k        a-posteriori covariance, after the epoch's updates and feedback reset
    Phi_k      transition of the error state from epoch k-1 (after its reset) to k
    P^-_k      a-priori covariance at k (before the epoch's updates) = Phi_k P_{k-1} Phi_k^T + Qd_k
    dx_k       what the updates at k estimated (and fed back), in the error state before the
               reset: 0 at an epoch without update
    G_k        how the reset maps the error state (post = G pre); the identity when the filter
               resets its state but not its covariance (every built-in filter)

The smoothed correction d_k is the smoothed error state relative to the forward solution at
k (after its reset), in the filter's own error convention; the filter applies it as it applies
its feedback. With ``d_N = 0`` and ``P^s_N = P_N`` at the last epoch (Rauch, Tung & Striebel
1965, in the error-state form)::

    C_k    = P_k Phi_{k+1}^T (P^-_{k+1})^-1                                              (1)
    d_k    = C_k (G_{k+1}^-1 d_{k+1} + dx_{k+1})                                         (2)
    P^s_k  = P_k + C_k (G_{k+1}^-1 P^s_{k+1} G_{k+1}^-T - P^-_{k+1}) C_k^T                 (3)

For an open-loop filter, whose state estimate x_k is not reset, ``dx_k = x_k - Phi_k x_{k-1}``
and the smoothed state is ``x_k + d_k``: (2) is then the textbook
``x^s_k = x_k + C_k (x^s_{k+1} - x^-_{k+1})``. A state with zero a-priori variance (a frozen
state) is known exactly: its column of the gain is 0 (the pseudo-inverse in (1)).

:func:`backward_chunk` runs (1)-(3) over the epochs of one chunk of the forward pass, latest
first, carrying what the epoch after the chunk contributes (:class:`Carry`), so a pass over a
day-long run holds one chunk at a time.
"""

from __future__ import annotations

import dataclasses

import numpy as np


@dataclasses.dataclass(frozen=True)
class Carry:
    """What epoch k+1 hands to epoch k in the backward pass: its smoothed correction ``d``
    (n,) and covariance ``P_s`` (n, n), and what the forward pass stored at it: the transition
    ``phi`` into it, its a-priori covariance ``P_prior``, its update ``dx`` and its reset
    ``reset`` (None: the identity)."""

    d: np.ndarray
    P_s: np.ndarray
    phi: np.ndarray
    P_prior: np.ndarray
    dx: np.ndarray
    reset: np.ndarray | None = None


def gains(P_post: np.ndarray, phi_next: np.ndarray, P_prior_next: np.ndarray) -> np.ndarray:
    """Smoother gains (1) of a stack of epochs: ``C_k = P_k Phi_{k+1}^T (P^-_{k+1})^+`` (m, n, n).

    ``P^-`` is inverted on the states it gives a positive variance; the other columns of C are
    0 (states known exactly). Raises ``np.linalg.LinAlgError`` when P^- is singular on them.
    """
    m, n, _ = P_post.shape
    # C^T = (P^-)^-1 Phi P (P, P^- symmetric)
    B = phi_next @ P_post
    active = np.diagonal(P_prior_next, axis1=1, axis2=2) > 0.0
    C_T = np.zeros((m, n, n))
    masks, groups = np.unique(active, axis=0, return_inverse=True)
    for g, mask in enumerate(masks):
        idx = np.flatnonzero(groups.reshape(-1) == g)
        sel = np.flatnonzero(mask)
        if sel.size == 0:
            continue
        A = P_prior_next[np.ix_(idx, sel, sel)]
        C_T[np.ix_(idx, sel, np.arange(n))] = np.linalg.solve(A, B[np.ix_(idx, sel,
                                                                         np.arange(n))])
    return np.swapaxes(C_T, 1, 2)


def backward_chunk(
    P_post: np.ndarray, phi: np.ndarray, P_prior: np.ndarray, dx: np.ndarray,
    carry: Carry | None, reset: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, Carry]:
    """Equations (1)-(3) over the m epochs of one chunk (arrays in time order).

    Parameters
    ----------
    P_post, P_prior : ndarray, shape (m, n, n)
    phi : ndarray, shape (m, n, n)
        Transition into each epoch from the one before.
    dx : ndarray, shape (m, n)
    carry : Carry or None
        From the chunk after this one (None: this chunk ends the run; its last epoch is the
        filter's own).
    reset : ndarray, shape (m, n, n), optional
        Reset Jacobians (None: identity).

    Returns
    -------
    d : ndarray, shape (m, n)
        Smoothed corrections.
    P_s : ndarray, shape (m, n, n)
        Smoothed covariances (symmetric).
    carry : Carry
        For the chunk before this one.
    """
    m, n = dx.shape
    d = np.empty((m, n))
    P_s = np.empty((m, n, n))
    if carry is None:
        last = m - 1
        d[last] = 0.0
        P_s[last] = P_post[last]
        nxt_phi, nxt_prior = phi[1:], P_prior[1:]
        nxt_dx = dx[1:]
        nxt_reset = None if reset is None else reset[1:]
    else:
        last = m
        nxt_phi = np.concatenate([phi[1:], carry.phi[None]])
        nxt_prior = np.concatenate([P_prior[1:], carry.P_prior[None]])
        nxt_dx = np.concatenate([dx[1:], carry.dx[None]])
        nxt_reset = None
        if reset is not None or carry.reset is not None:
            eye = np.eye(n)
            mine = reset[1:] if reset is not None else np.broadcast_to(eye, (m - 1, n, n))
            nxt_reset = np.concatenate([mine, (eye if carry.reset is None
                                               else carry.reset)[None]])
    if last > 0:
        C = gains(P_post[:last], nxt_phi, nxt_prior)
        G_inv = None if nxt_reset is None else np.linalg.inv(nxt_reset)
        d_next = carry.d if carry is not None else d[last]
        Ps_next = carry.P_s if carry is not None else P_s[last]
        for k in range(last - 1, -1, -1):
            if G_inv is not None:
                d_next = G_inv[k] @ d_next
                Ps_next = G_inv[k] @ Ps_next @ G_inv[k].T
            d[k] = C[k] @ (d_next + nxt_dx[k])  # (2)
            Ck = C[k]
            S = P_post[k] + Ck @ (Ps_next - nxt_prior[k]) @ Ck.T  # (3)
            P_s[k] = 0.5 * (S + S.T)
            d_next, Ps_next = d[k], P_s[k]
    first = Carry(d[0].copy(), P_s[0].copy(), phi[0].copy(), P_prior[0].copy(), dx[0].copy(),
                  None if reset is None else reset[0].copy())
    return d, P_s, first


def smooth(P_post: np.ndarray, phi: np.ndarray, P_prior: np.ndarray, dx: np.ndarray,
           reset: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """The backward pass over a whole run in memory: :func:`backward_chunk` on one chunk."""
    d, P_s, _ = backward_chunk(P_post, phi, P_prior, dx, None, reset)
    return d, P_s
