"""The fast paths' memos: ``once`` makes each entry once; ``Recent`` stays bounded and forgets
the entry used longest ago."""
from khepera_noise_ros.memo import Recent, once


def test_a_memo_makes_each_entry_once_keeps_the_recently_used_and_stays_bounded():
    made = []

    def make(key):
        made.append(key)
        return key * 10

    memo = Recent(2)
    assert memo.recall(1, lambda: make(1)) == 10
    assert memo.recall(2, lambda: make(2)) == 20
    assert memo.recall(1, lambda: make(1)) == 10        # remembered: not made again
    assert memo.recall(3, lambda: make(3)) == 30        # drops 2, used longest ago
    assert made == [1, 2, 3]
    assert sorted(memo) == [1, 3]
    memo.recall(2, lambda: make(2))
    assert made == [1, 2, 3, 2] and sorted(memo) == [2, 3] and len(memo) == 2


def test_once_makes_an_entry_the_first_time_only():
    made = []
    memo: dict = {}
    assert once(memo, 'a', lambda: made.append('a') or 1) == 1
    assert once(memo, 'a', lambda: made.append('again') or 2) == 1
    assert made == ['a'] and memo == {'a': 1}
