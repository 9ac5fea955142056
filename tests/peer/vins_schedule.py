"""VINS for the test peers: the sequence's poses on the mock camera's looped clock, as a
node that shares no code with polymap would rebuild it from poses.txt. Plain Python, so
both the ROS 2 peer (the venv's python) and the ROS 1 peer (Debian's, for rospy) use it."""

from polymap_sequence import read_poses


class Schedule:
    """Each frame's pose when the loop shows it (mock/clock.rs's rule: the loop walks the
    sequence forward and then back, so its period is twice the walk; frame k is shown at
    offset stamp_k - first on the way out and 2 * span - (stamp_k - first) on the way back,
    the last and first frames once each)."""

    def __init__(self, seq):
        poses = read_poses(seq)
        first, last = poses[0][0], poses[-1][0]
        self.period = 2 * (last - first)
        shown = [(stamp - first, p, q) for stamp, p, q in poses]
        shown += [(self.period - (stamp - first), p, q) for stamp, p, q in poses[1:-1]]
        self.shown_at = sorted(shown, key=lambda s: s[0])
        self.sent = set()

    def due(self, now, window_ns=100_000_000):
        """(stamp, position, quaternion) of every frame shown in the last `window_ns` not yet
        returned, stamped as the camera stamps it."""
        loop_start = now - now % self.period
        out = []
        for base in (loop_start - self.period, loop_start):
            for offset, p, q in self.shown_at:
                shown = base + offset
                if now - window_ns <= shown <= now and shown not in self.sent:
                    self.sent.add(shown)
                    out.append((shown, p, q))
        return out
