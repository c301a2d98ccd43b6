"""A hidden-target env whose only informative reward is an episode's last: the point on a line must end its
10-step episodes within 0.1 of a target it never observes, and it is paid -|x - target| at the last step, 0
before. docs/icrl-your-env.md's env with its dense reward moved to the episode's end (a success bonus, as on
MountainCar), for the last-reward measurement (README.md here)."""
import gymnasium as gym
import numpy as np

from vintix.demonstrators.posterior import PosteriorSamplingDemonstrator, PosteriorSettings

STEPS, SPEED, RADIUS = 10, 0.3, 0.1


class TerminalTargetEnv(gym.Env):
    observation_space = gym.spaces.Box(-2.0, 2.0, (1,), np.float32)
    action_space = gym.spaces.Box(-1.0, 1.0, (1,), np.float32)

    def __init__(self):
        self.target, self.x, self.t = np.zeros(1), np.zeros(1), 0

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        if seed is not None:  # vintix seeds each env's first reset: the env's target for its whole life
            self.target = np.random.default_rng(seed).uniform(-1.0, 1.0, 1)
        self.x, self.t = np.zeros(1), 0
        return self.x.astype(np.float32), {}

    def step(self, action):
        self.x = np.clip(self.x + SPEED * np.clip(action, -1.0, 1.0), -2.0, 2.0)
        self.t += 1
        done = self.t == STEPS
        success = float(done and abs(self.x[0] - self.target[0]) < RADIUS)
        return self.x.astype(np.float32), float(self.rewards_under_goals(self.target[None])[0]), False, done, \
            {"success": success}

    # For the demonstrator only: the prior, the reward under other targets, the true target.
    def goal_box(self):
        return np.array([-1.0]), np.array([1.0])

    def goal_prior(self, rng, count):
        return rng.uniform(-1.0, 1.0, (count, 1))

    def rewards_under_goals(self, goals, action=None):
        paid = self.t == STEPS  # nothing before the episode's last step
        return -np.abs(self.x - goals)[:, 0] * paid

    @property
    def true_goal(self):
        return self.target.copy()


class Expert:
    """Straight at the target, as fast as the action bounds allow; `act_toward` aims at a given one."""

    def act(self, observations, envs):
        return self.act_toward(observations, np.stack([env.unwrapped.true_goal for env in envs]))

    def act_toward(self, observations, goals):
        return np.clip((goals - observations) / SPEED, -1.0, 1.0)


def make_demonstrator(task):
    """Probe the line's low end for the whole first episode (its one reward, -(target + 1), names the target),
    then aim at the likeliest target."""
    return PosteriorSamplingDemonstrator(Expert(), PosteriorSettings(probe_steps=STEPS, update_every=1,
                                                                     reward_tolerance=0.05))
