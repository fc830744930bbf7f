"""Point to the drive: candidates refused only for a size their joint's drive never shows.

A robot file without ``drive:`` gives every joint a gear train; a cable- or belt-driven
joint then yields, lags and slips by sizes diagnosis refuses as implausible
(``effects.drives``). Where another drive shows those sizes
(``CandidateTest.drives``), the user hears it once per joint, with the robot-file line
that would allow it; the diagnosis never switches a drive by itself. Only candidates
among the strongest of their round are named (``STRONG``): one that explains a sliver of
what another explains stands in for it, and so does one whose pattern a candidate added
in its round explains as well. Where a cable or a belt would allow the sizes and the
joint is in no declared transmission group, the line adds that its motors may turn other
joints too, and how to declare them.
"""

from __future__ import annotations

from ..model.transmission import group_of
from ..results import CalibrationResult, Decision

STRONG = 0.5  # of the round's largest residual drop a candidate must explain to be named


def was_added(result: CalibrationResult, effect: str, joints) -> bool:
    """Whether an effect ``effect`` the calibration added holds every joint of ``joints``
    (a unit tested alone is added as part of the finding of its type)."""
    return any(e.name == effect and set(joints) <= set(e.joints) for e in result.effects)


def drive_lines(result: CalibrationResult) -> list[str]:
    """Once per joint: the candidates refused only for a size its drive never shows that
    another drive shows, with the robot-file line that would allow them. Nothing is
    switched: the drive is the user's to declare."""
    labels: dict[int, list[str]] = {}
    allowing: dict[int, list[str]] = {}
    strongest: dict[int, float] = {}  # per round, the largest share any candidate explains
    taken: dict[int, float] = {}  # per round, the share the candidate added explains
    for test in result.diagnosis:
        entry = test.as_dict()
        drop, round_ = float(entry.get("rss_drop", 0.0)), entry.get("round", 0)
        strongest[round_] = max(strongest.get(round_, 0.0), drop)
        if test.outcome is Decision.ADDED:
            taken[round_] = max(taken.get(round_, 0.0), drop)
    for test in result.diagnosis:
        if test.outcome is not Decision.IMPLAUSIBLE or was_added(result, test.effect, test.joints):
            continue
        entry = test.as_dict()
        # a candidate that explains a sliver of what a stronger one explains stands in
        # for it: pointing to its drive would send the user the wrong way
        drop, round_ = float(entry.get("rss_drop", 0.0)), entry.get("round", 0)
        if not drop >= STRONG * strongest[round_] or taken.get(round_, 0.0) >= drop:
            continue
        label = test.label or f"{test.effect}{list(test.joints)}"
        for joint, drives in getattr(test, "drives", ()):
            if label not in labels.setdefault(joint, []):
                labels[joint].append(label)
            common = [d for d in allowing.get(joint, drives) if d in drives]
            allowing[joint] = common or list(allowing.get(joint, drives))
    lines = []
    for joint, names in labels.items():
        drive, others = allowing[joint][0], allowing[joint][1:]
        also = f" (or {', '.join(others)})" if others else ""
        article = "an" if drive[0] in "aeiou" else "a"
        lines.append(f"joint {joint}: {', '.join(names)} refused for sizes a "
                     f"{result.robot_nominal.drive(joint)} drive never shows, ordinary for "
                     f"{article} {drive} drive{also}; if joint {joint} is one, give its entry "
                     f"in the robot file `drive: {drive}` (the drive is never switched "
                     f"without it){_coupling_hint(result, joint, allowing[joint])}")
    return lines


def _coupling_hint(result: CalibrationResult, joint: int, drives) -> str:
    """Where cables or belts would allow the sizes and the joint is in no declared
    transmission group: that its motors may drive it together with other joints, and how
    to say so (the coupled effects are offered only then)."""
    if not {"cable", "belt"} & set(drives) or \
            group_of(result.robot_nominal.transmission, joint) is not None:
        return ""
    return (f"; if its motors also turn other joints (a differential), list them with joint "
            f"{joint} under `transmission:` to have their coupled compliance and motor play "
            f"tried")
