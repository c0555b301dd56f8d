"""The option census: dead (empty-set) options are told apart from usable ones."""

import doctest

import torch

from skillchain_torch.options import OptionBank, OptionStatus
from skillchain_torch.trainers.study import option_census


def test_doctest():
    assert doctest.testmod(option_census).failed == 0


def test_an_option_fitted_on_one_failure_is_dead(tmp_path, capsys):
    bank = OptionBank.build(population=2, slots=3, order=1, capacity=8)
    bank.status[:, :2] = int(OptionStatus.LEARNING)
    clf = bank.classifier
    far = torch.tensor([[0.2, 0.9, 0.5, 0.5]], dtype=torch.float64)
    clf.add_examples(0, 0, far, torch.zeros(1))   # agent 0, slot 0: one failure, then a fit
    clf.fit()
    c = option_census.census(bank, resolution=6)
    assert c["executable"].tolist() == [2, 2]
    assert c["dead"].tolist() == [1, 0] and c["usable"].tolist() == [1, 2]
    assert c["coverage"].tolist() == [1.0, 1.0]  # untrained slots hold everything
    bank.save(tmp_path / "options.pt")
    assert option_census.main([str(tmp_path), "--resolution", "4"]) == 0
    assert "2 agents; 0 (0%) end with no usable option" in capsys.readouterr().out
