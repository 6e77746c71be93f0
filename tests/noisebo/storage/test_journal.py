import numpy as np
import pytest

from noisebo.storage import journal
from noisebo.storage.journal import JournalError, JournalWriter, Record


def records():
    return [
        Record("campaign", {"seed": 1, "nan": float("nan")}),
        Record("shot", {"value": 1.25}, {"spectrum": np.arange(6, dtype=np.float32).reshape(2, 3)}),
        Record("point", {"index": 0}),
    ]


def write(path, items):
    w = JournalWriter.create(path, items[0])
    for r in items[1:]:
        w.append(r)
    w.close()


def test_round_trip_keeps_fields_and_arrays(tmp_path):
    path = tmp_path / "j.journal"
    write(path, records())
    got, length = journal.read(path)
    assert length == path.stat().st_size
    assert [r.type for r in got] == ["campaign", "shot", "point"]
    assert np.isnan(got[0].fields["nan"]) and got[1].fields["value"] == 1.25
    np.testing.assert_array_equal(got[1].arrays["spectrum"], np.arange(6, dtype=np.float32).reshape(2, 3))
    assert got[1].arrays["spectrum"].dtype == np.float32


@pytest.mark.parametrize("cut", [1, 10, 25])
def test_a_torn_tail_is_not_read_and_is_cut_on_reopen(tmp_path, cut):
    path = tmp_path / "j.journal"
    write(path, records())
    full = path.read_bytes()
    frame = journal.encode(records()[2])
    path.write_bytes(full[: len(full) - len(frame) + cut])
    got, length = journal.read(path)
    assert [r.type for r in got] == ["campaign", "shot"]
    w = JournalWriter.open(path)
    w.truncate_to(length)
    w.append(records()[2])
    w.close()
    assert [r.type for r in journal.read(path)[0]] == ["campaign", "shot", "point"]


def test_a_corrupt_byte_before_the_end_is_an_error_naming_the_record_not_a_shorter_journal(tmp_path):
    path = tmp_path / "j.journal"
    write(path, records())
    data = bytearray(path.read_bytes())
    first = len(journal.encode(records()[0]))
    data[first + 30] ^= 0xFF  # inside the second record; the third still reads
    path.write_bytes(bytes(data))
    with pytest.raises(
        journal.JournalDamaged,
        match=rf"record 1 \(at byte {first}\) is damaged and 1 intact records "
        rf"follow it; records 0-0 \(bytes 0-{first - 1}\) are intact",
    ):
        journal.read(path)
    found, length, damage = journal.scan(path)
    assert [r.type for r in found] == ["campaign"] and length == first
    assert (damage.record, damage.offset, damage.intact_after, damage.torn) == (1, first, 1, False)


def test_one_writer_at_a_time(tmp_path):
    path = tmp_path / "j.journal"
    first = JournalWriter.create(path, records()[0])
    with pytest.raises(JournalError, match="in use by another running campaign"):
        JournalWriter.open(path)
    first.append(records()[1])
    first.close()
    assert len(journal.read(path)[0]) == 2


def test_create_refuses_an_existing_journal(tmp_path):
    path = tmp_path / "j.journal"
    path.write_bytes(b"")
    with pytest.raises(JournalError, match="already exists"):
        JournalWriter.create(path, records()[0])
    assert path.read_bytes() == b"" and sorted(tmp_path.iterdir()) == [path]
