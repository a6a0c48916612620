"""A user agent loaded by `--agent tests.example_agent:TurnInPlaceAgent` (the README's plug-in example)."""


class TurnInPlaceAgent:
    privileged = False

    def reset(self, episode_info: dict) -> None:
        self.steps = 0

    def act(self, observation: dict) -> int:
        self.steps += 1
        return 0 if self.steps > 12 else 2  # turn left 12 times, then STOP
