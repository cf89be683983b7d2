"""A user's own vigilance module, in one short file: raise s_vig after every failure."""

from pydantic import Field

from sfl_brain.messages import Rejected, Threshold, TrialDone, VigilanceStart
from sfl_brain.module import Module, ModuleParams, on


class CautiousVigilance(Module):
    """Start bold; every failure makes the decision more cautious by ``step``."""

    class Params(ModuleParams):
        start: float = Field(-0.3, ge=-2, le=2)
        step: float = Field(0.02, gt=0)

    def reset(self, seed: int) -> None:
        self.s_vig = self.params.start

    def threshold(self) -> Threshold:
        return Threshold(s_vig=self.s_vig, low=self.s_vig, high=self.s_vig)

    @on(VigilanceStart)
    def start(self, msg: VigilanceStart) -> Threshold:
        return self.threshold()

    @on(TrialDone)
    def trial_done(self, msg: TrialDone) -> Threshold:
        if not msg.success:
            self.s_vig += self.params.step
        return self.threshold()

    @on(Rejected)
    def rejected(self, msg: Rejected) -> Threshold:
        return self.threshold()
