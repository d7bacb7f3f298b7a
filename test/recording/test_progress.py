"""``track``: a bar over a loop, quiet off a terminal; lines printed meanwhile erase it first."""
import io

from accelcal_ros.recording.progress import Progress, track


def test_track_is_quiet_off_a_terminal(capsys):
    """Not a terminal: the items pass through, nothing is drawn, stdout is untouched."""
    stream = io.StringIO()
    seen = []
    for item in track(['a', 'b', 'c'], 'trials', stream=stream):
        print(item)
        seen.append(item)
    assert seen == ['a', 'b', 'c']
    assert stream.getvalue() == ''
    assert capsys.readouterr().out == 'a\nb\nc\n'


def test_track_draws_and_clears_before_printed_lines(monkeypatch, capsys):
    """Forced on: one unit per item, 100 % at the end; a printed line erases the bar first."""
    monkeypatch.setenv('ACCELCAL_PROGRESS', '1')
    stream = io.StringIO()
    for item in track(range(4), 'study', stream=stream):
        if item == 2:
            print('row 2')
    text = stream.getvalue()
    assert 'study [' in text and '25% 1/4' in text and '100% 4/4' in text
    assert text.endswith('\n')
    assert '\r\x1b[K' in text    # erased before 'row 2' was printed
    assert capsys.readouterr().out == 'row 2\n'


def test_track_without_length_counts_and_ends_on_an_exception(monkeypatch):
    """A generator has no length: a count without a bar; the line ends on an exception."""
    monkeypatch.setenv('ACCELCAL_PROGRESS', '1')
    stream = io.StringIO()
    try:
        for item in track((k for k in range(3)), 'reading', stream=stream):
            if item == 1:
                raise ValueError('stop')
    except ValueError:
        pass
    assert 'reading 1' in stream.getvalue() and stream.getvalue().endswith('\n')


def test_clear_erases_only_a_drawn_bar(monkeypatch):
    """clear() writes nothing before a bar is drawn, and the erase sequence after."""
    monkeypatch.setenv('ACCELCAL_PROGRESS', '1')
    stream = io.StringIO()
    bar = Progress(3, 'fits', stream=stream, min_interval_s=0.0)
    bar.clear()
    assert stream.getvalue() == ''
    bar.update()
    bar.clear()
    assert stream.getvalue().endswith('\r\x1b[K')
    bar.close()


def test_only_the_outermost_bar_is_drawn(monkeypatch):
    """A bar opened inside another's loop counts silently; after both close, bars draw again."""
    monkeypatch.setenv('ACCELCAL_PROGRESS', '1')
    outer, inner = io.StringIO(), io.StringIO()
    for _ in track(range(2), 'study', stream=outer):
        for _ in track(range(3), 'positions', stream=inner):
            pass
    assert 'study [' in outer.getvalue() and inner.getvalue() == ''
    bar = Progress(1, 'again', stream=inner)
    assert bar.enabled
    bar.close(erase=True)
    assert not bar.enabled
