"""Figure 4a's three agents at order 5 (the runaway fix), 100 runs x 250 episodes, seeds 1000+."""
import sys
from pathlib import Path

from skillchain_torch.trainers.study.paper_report import write_report
from skillchain_torch.trainers.study.reproduce import paper_experiments, run_experiments

out = Path(sys.argv[1])
exps = paper_experiments(runs=100, episodes=250, instances=("simple",), order=5)
print([(e.name, e.config.order, e.config.alpha) for e in exps], flush=True)
run_experiments(exps, out, jobs=2, quiet=True)
write_report(out, [e.name for e in exps], quiet=True)
