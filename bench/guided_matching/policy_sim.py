#!/usr/bin/env python3
"""Replays vocabtree pair-selection policies against exhaustive matching's ground truth.

Matching and verification are replaced by a lookup in exhaustive's verified pairs, so a policy
is scored in a second: pairs matched, exhaustive's verified pairs found (plain and inlier-
weighted) and a modelled time (seconds per failing and per verified pair, measured). Used to
choose the defaults of `loopsfm match --pairs vocabtree` (matching/guided_pairing); the
policies here mirror that code, the C++ is what runs.

    python3 policy_sim.py --truth RUN/exhaustive-0/result.json --similarity SIM.txt \
        [--fail-ms 4.5 --verified-ms 6.3]

SIM.txt comes from `loopsfm match --pairs vocabtree --similarity-out SIM.txt`; the truth from
guided_matching.py's workdir (or any JSON with {"verified": {"k,l": inliers}} over frame
indices in capture order). Standard library only.
"""

import argparse
import heapq
import json


def load_truth(path):
    verified = json.load(open(path))["verified"]
    return {tuple(map(int, k.split(","))): v for k, v in verified.items()}


def load_similarity(path):
    with open(path) as f:
        f.readline()
        return [[float(x) for x in line.split()] for line in f]


class Replay:
    """Matches pairs by looking them up in the truth; counts what was matched."""

    def __init__(self, truth, n):
        self.truth, self.n = truth, n
        self.tried, self.found = set(), {}

    def match(self, pairs):
        ok = []
        for p in pairs:
            self.tried.add(p)
            good = p in self.truth
            if good:
                self.found[p] = self.truth[p]
            ok.append(good)
        return ok


def sequential_waves(replay, overlap=10, initial_overlap=30, initial_frames=10):
    n = replay.n
    open_ = [True] * n
    for d in range(1, n):
        wave = [(i, i + d) for i in range(n - d)
                if open_[i] and d <= (initial_overlap if i < initial_frames else overlap)]
        if not wave:
            break
        for (i, _), ok in zip(wave, replay.match(wave)):
            open_[i] = ok


def best_untried(scores, tried, proposed, k):
    n = len(scores)
    candidates = ((max(scores[i][j], scores[j][i]), -i, -j) for i in range(n)
                  for j in range(i + 1, n) if (i, j) not in tried and (i, j) not in proposed)
    return [(-i, -j) for _, i, j in heapq.nlargest(k, candidates)]


def guided_rounds(replay, scores, k, max_failure_ratio=0.7, adaptive_k=False,
                  score_stop=None, neighbours=4, min_k=0):
    """The rounds of guided_pairing. adaptive_k: the next round proposes by score as many
    pairs as this round's score proposals verified (at least min_k); score_stop: stop
    proposing by score once fewer than this fraction of a round's score proposals verify;
    the rounds end when nothing is proposed or (with neither) by max_failure_ratio."""
    n = replay.n
    steps = [(-1, 0), (1, 0), (0, -1), (0, 1)]
    if neighbours == 8:
        steps += [(-1, -1), (1, 1), (-1, 1), (1, -1)]
    last, rounds, score_k, scoring = [], [], k, True
    while True:
        proposed, props = set(), []

        def propose(i, j):
            if i == j or min(i, j) < 0 or max(i, j) >= n:
                return False
            p = (min(i, j), max(i, j))
            if p in replay.tried or p in proposed:
                return False
            proposed.add(p)
            props.append(p)
            return True

        for i, j in last:
            for di, dj in steps:
                propose(i + di, j + dj)
        first_score = len(props)
        if scoring and score_k > 0:
            for p in best_untried(scores, replay.tried, proposed, score_k):
                propose(*p)
        if not props:
            break
        ok = replay.match(props)
        last = [p for p, good in zip(props, ok) if good]
        score_props = len(props) - first_score
        score_ok = sum(ok[first_score:])
        rounds.append((first_score, sum(ok[:first_score]), score_props, score_ok))
        if adaptive_k or score_stop is not None:
            if score_props and score_stop is not None and score_ok < score_stop * score_props:
                scoring = False
            if adaptive_k:
                score_k = max(min_k, score_ok)
            if not last and not scoring:
                break
            if not last and score_ok == 0:
                break
        elif len(props) - sum(ok) > max_failure_ratio * len(props):
            break
    return rounds


def evaluate(truth, scores, fail_ms, verified_ms, **policy):
    n = len(scores)
    replay = Replay(truth, n)
    sequential_waves(replay)
    seq = len(replay.tried)
    rounds = guided_rounds(replay, scores, **policy)
    total = sum(truth.values())
    matched = len(replay.tried)
    found = len(replay.found)
    seconds = ((matched - found) * fail_ms + found * verified_ms) / 1000.0
    return {"matched": matched, "sequential": seq, "rounds": len(rounds), "found": found,
            "pair_recall": found / len(truth), "weighted": sum(replay.found.values()) / total,
            "wasted": matched - found, "seconds": seconds}


def main():
    p = argparse.ArgumentParser(description=__doc__,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--truth", required=True)
    p.add_argument("--similarity", required=True)
    p.add_argument("--fail-ms", type=float, default=4.5,
                   help="seconds per failing pair (ms): matching only")
    p.add_argument("--verified-ms", type=float, default=6.3,
                   help="per verified pair (ms): matching and a full verification")
    args = p.parse_args()
    truth, scores = load_truth(args.truth), load_similarity(args.similarity)
    n = len(scores)
    exhaustive = (n * (n - 1) // 2 - len(truth)) * args.fail_ms / 1000 + \
        len(truth) * args.verified_ms / 1000
    optimum = exhaustive * len(truth) / (n * (n - 1) // 2)
    print(f"{n} frames, {len(truth)} true pairs; modelled exhaustive {exhaustive:.1f} s, "
          f"optimum (x density) {optimum:.1f} s, true pairs only "
          f"{len(truth) * args.verified_ms / 1000:.1f} s")
    policies = {
        "current (k=n, stop 0.7)": dict(k=n),
        "k=n, stop 0.5": dict(k=n, max_failure_ratio=0.5),
        "k=n/2": dict(k=n // 2),
        "adaptive k": dict(k=n, adaptive_k=True),
        "adaptive k, min n/10": dict(k=n, adaptive_k=True, min_k=n // 10),
        "score stop 0.3": dict(k=n, score_stop=0.3),
        "score stop 0.5": dict(k=n, score_stop=0.5),
        "adaptive k + score stop 0.3": dict(k=n, adaptive_k=True, score_stop=0.3),
        "adaptive k + score stop 0.5": dict(k=n, adaptive_k=True, score_stop=0.5),
        "8-neighbours, adaptive + stop 0.3": dict(k=n, adaptive_k=True, score_stop=0.3,
                                                  neighbours=8),
    }
    print(f"| policy | matched | wasted | rounds | pair recall | inlier-weighted | "
          f"modelled s | / optimum |")
    print("|---|---|---|---|---|---|---|---|")
    for name, policy in policies.items():
        r = evaluate(truth, scores, args.fail_ms, args.verified_ms, **policy)
        print(f"| {name} | {r['matched']} | {r['wasted']} | {r['rounds']} | "
              f"{100 * r['pair_recall']:.1f} % | {100 * r['weighted']:.2f} % | "
              f"{r['seconds']:.1f} | {r['seconds'] / optimum:.2f} |")


if __name__ == "__main__":
    main()
