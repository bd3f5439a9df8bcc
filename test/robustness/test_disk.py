"""A full or read-only disk: a one-line error that says so, and nothing already written lost.

Two ways: simulated (the write or the temporary file raises ENOSPC / EROFS / EACCES, by
monkeypatching ``os``), which always runs; and real, on a 64 KiB tmpfs and a read-only
bind mount, which needs the right to mount (root in a container that allows it) and is
skipped otherwise.  Root ignores file permissions, so chmod cannot stand for a read-only
directory here.
"""
from __future__ import annotations

import errno
import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

from khepera_noise_ros import cli, files, recording
from khepera_noise_ros.bag import read_bag, write_bag
from khepera_noise_ros.nodes.checkpoint import Checkpoint
from khepera_noise_ros.testing.recordings import sample_recording


def one_line(text: str) -> str:
    assert text and '\n' not in text.strip(), text
    return text


class Refusing:
    """A file object whose writes fail as a full disk's do after ``allowed`` bytes."""

    def __init__(self, inner, code: int, allowed: int = 10):
        self.inner, self.code, self.allowed = inner, code, allowed

    def write(self, data):
        if len(data) > self.allowed:
            self.inner.write(data[:self.allowed])
            raise OSError(self.code, os.strerror(self.code))
        self.allowed -= len(data)
        return self.inner.write(data)

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        return self.inner.__exit__(*exc)


@pytest.fixture
def full_disk(monkeypatch):
    """Every file opened by the atomic writer runs out of space after a few bytes."""
    fdopen = os.fdopen
    monkeypatch.setattr(files.os, 'fdopen',
                        lambda *a, **k: Refusing(fdopen(*a, **k), errno.ENOSPC))


@pytest.mark.parametrize('code, says', [(errno.EROFS, 'read-only file system (EROFS)'),
                                        (errno.EACCES, 'permission denied (EACCES)')])
def test_a_directory_that_takes_no_file_is_named_with_why(tmp_path, monkeypatch, code, says):
    target = tmp_path / 'results.json'
    files.write_json(target, {'kept': True})

    def refuse(*args, **kwargs):
        raise OSError(code, os.strerror(code))
    monkeypatch.setattr(files.tempfile, 'mkstemp', refuse)
    with pytest.raises(files.WriteError) as caught:
        files.write_json(target, {'kept': False})
    assert one_line(str(caught.value)) == (f'cannot write {target}: {says}; its earlier '
                                           'content is unchanged')
    assert json.loads(target.read_text()) == {'kept': True}


def test_results_on_a_full_disk_keep_the_earlier_file_and_leave_no_debris(
        tmp_path,
        full_disk):
    target = tmp_path / 'results.json'
    target.write_text('{"kept": true}\n')
    with pytest.raises(files.WriteError, match=r'no space left on the device \(ENOSPC\); '
                                               r'its earlier content is unchanged'):
        files.write_json(target, {'big': list(range(1000))})
    assert target.read_text() == '{"kept": true}\n'
    assert sorted(p.name for p in tmp_path.iterdir()) == ['results.json']
    with pytest.raises(files.WriteError, match='nothing was written there'):
        files.write_json(tmp_path / 'new.json', {'big': list(range(1000))})
    assert not (tmp_path / 'new.json').exists()


def test_a_checkpoint_on_a_full_disk_leaves_the_last_one_whole(tmp_path, monkeypatch):
    checkpoint = Checkpoint(tmp_path / 'run.checkpoint.json', {'seed': 1})
    run = checkpoint.evaluator(lambda g, s: np.full(len(s), 0.5))
    run(np.zeros((2, 20)), np.arange(2))
    checkpoint.save(generation=0)
    run(np.ones((2, 20)), np.arange(2))
    fdopen = os.fdopen
    monkeypatch.setattr(files.os, 'fdopen',
                        lambda *a, **k: Refusing(fdopen(*a, **k), errno.ENOSPC))
    with pytest.raises(files.WriteError):
        checkpoint.save(generation=1)
    monkeypatch.undo()
    again = Checkpoint(tmp_path / 'run.checkpoint.json', {'seed': 1})
    assert again.load() and again.loaded == 1 and again.state['generation'] == 0


def test_a_recording_on_a_full_disk_keeps_the_earlier_csv_yaml_and_bag(tmp_path, monkeypatch):
    rec = sample_recording()
    csv_path, yaml_path = recording.write_csv(rec, tmp_path / 'rec')
    bag = write_bag(rec, tmp_path / 'rec_bag')
    before = {p: p.read_bytes() for p in (csv_path, yaml_path)}
    fdopen = os.fdopen
    monkeypatch.setattr(files.os, 'fdopen',
                        lambda *a, **k: Refusing(fdopen(*a, **k), errno.ENOSPC))
    with pytest.raises(files.WriteError, match='cannot write .*rec.csv: no space left'):
        recording.write_csv(rec.select(rec.step < 3), tmp_path / 'rec')

    def full(*args, **kwargs):
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
    monkeypatch.setattr(files.os, 'replace', full)     # the bag is staged, then swapped in
    with pytest.raises(OSError) as caught:             # from rosbags, or from the swap
        write_bag(rec.select(rec.step < 3), tmp_path / 'rec_bag', overwrite=True)
    assert files.refused(caught.value)
    assert one_line(files.describe(caught.value)).startswith('cannot write')
    monkeypatch.undo()
    assert {p: p.read_bytes() for p in before} == before
    assert len(read_bag(bag)) == len(rec) == len(recording.load(csv_path))


def test_the_command_line_says_the_disk_is_full_in_one_line(tmp_path, full_disk, capsys):
    out = tmp_path / 'evolve.json'
    status = cli.main(['evolve', '--population', '4', '--generations', '1', '--steps', '5',
                       '--quiet', '--out', str(out)])
    err = capsys.readouterr().err
    assert status == 1
    assert one_line(err) == (f'khepera-noise evolve: error: cannot write {out}: no space left '
                             'on the device (ENOSPC); nothing was written there\n')


# -- a real small disk and a real read-only directory --------------------------------------

def mount(args: list[str]) -> bool:
    return subprocess.run(['mount', *args], capture_output=True).returncode == 0


@pytest.fixture
def tiny_disk(tmp_path):
    where = tmp_path / 'tiny'
    where.mkdir()
    if not mount(['-t', 'tmpfs', '-o', 'size=64k', 'tmpfs', str(where)]):
        pytest.skip('cannot mount a tmpfs here (needs root and a container that allows it)')
    yield where
    subprocess.run(['umount', str(where)], check=True)


@pytest.fixture
def read_only(tmp_path):
    source, where = tmp_path / 'source', tmp_path / 'ro'
    source.mkdir()
    where.mkdir()
    (source / 'results.json').write_text('{"kept": true}\n')
    if not mount(['--bind', str(source), str(where)]):
        pytest.skip('cannot bind-mount here (needs root and a container that allows it)')
    try:
        if not mount(['-o', 'remount,bind,ro', str(where)]):
            pytest.skip('cannot remount read-only here')
        yield where
    finally:
        subprocess.run(['umount', str(where)], check=True)


def test_a_real_full_disk_keeps_what_it_holds(tiny_disk):
    files.write_json(tiny_disk / 'small.json', {'kept': True})
    with pytest.raises(files.WriteError, match=r'no space left on the device \(ENOSPC\)'):
        files.write_json(tiny_disk / 'small.json', {'big': 'x' * 200_000})
    assert json.loads((tiny_disk / 'small.json').read_text()) == {'kept': True}
    assert [p.name for p in tiny_disk.iterdir()] == ['small.json']


def test_a_real_read_only_directory_is_named(read_only, capsys):
    target = read_only / 'results.json'
    status = cli.main(['evolve', '--population', '4', '--generations', '1', '--steps', '5',
                       '--quiet', '--out', str(target)])
    assert status == 1
    assert one_line(capsys.readouterr().err) == (
        f'khepera-noise evolve: error: cannot write {target}: read-only file system (EROFS); '
        'its earlier content is unchanged\n')
    assert Path(target).read_text() == '{"kept": true}\n'
