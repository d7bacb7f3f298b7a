"""The warnings panel of rig.png: every warning whole, wrapped to the panel's width."""
from accelcal_ros.rig.report import _warning_text


def test_warnings_are_wrapped_not_cut():
    """Long warnings keep every word; no line is wider than the panel; extras counted."""
    long = ('camera cam2: only 3 views cover the image corners; add poses where the board '
            'is near the left and right edges of cam2, tilted 30 to 50 deg, then calibrate '
            'again (views pose03 pose07 pose11 have RMS above 0.8 px)')
    warnings = [long] + [f'warning {k}' for k in range(9)]
    text = _warning_text(warnings, 55)
    lines = text.splitlines()
    assert max(len(line) for line in lines) <= 55
    assert f'- {long} - warning 0' in ' '.join(text.split())   # every word, in order
    assert lines[-1] == '... and 2 more (see the report)'
