"""The numbers to beat: the dissertation's tables 5-1..5-4 (Ea mm, sigma, Ep %).

"lsq" is the dissertation's "least square fitting" column; which degree it
used is not certain (see the table anomalies in docs/method.md), so we compare it
with our best least-squares degree.
"""

TABLES = {
    "sample1": {
        "captured": (7.2137, 3.4139, 22.2490),
        "spline": (6.9550, 3.3760, 21.4510),
        "nearest": (6.8070, 3.3608, 20.9946),
        "lsq": (0.6573, 7.3183e-15, 2.0273),
    },
    "sample2": {
        "captured": (3.7843, 1.1701, 10.9313),
        "spline": (3.1483, 1.1003, 9.0939),
        "nearest": (3.3748, 1.1243, 9.0939),
        "lsq": (0.6658, 0.2201, 1.9231),
    },
    "sample3": {
        "captured": (3.7318, 3.3894, 7.4925),
        "spline": (0.4913, 0.6353, 0.9864),
        "nearest": (0.5290, 0.6771, 1.0621),
        "lsq": (0.5319, 0.5393, 1.0678),
    },
    "sample4": {
        "captured": (2.4745, 2.0145, 8.7256),
        "spline": (2.4745, 2.0145, 8.7256),
        "nearest": (2.4746, 2.0145, 8.7258),
        "lsq": (2.4648, 2.0353, 8.6913),
    },
}


def best_ea(sample: str) -> float:
    return min(v[0] for v in TABLES[sample].values())
