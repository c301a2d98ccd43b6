"""Stage `train`: Algorithm Distillation over learning-history windows (CPU, one GPU, torchrun DDP)."""

from vintix.train.config import ConfigError, TrainConfig, load_config
from vintix.train.data import (
    TrainingData,
    TrainingDataError,
    WindowBatches,
    WindowDataset,
    collate_windows,
    load_training_data,
)
from vintix.train.trainer import (
    Callback,
    NonFiniteLossError,
    Scorer,
    Trainer,
    WindowLoss,
    build_optimizer,
    learning_rate,
    train,
)

__all__ = [
    "Callback",
    "ConfigError",
    "NonFiniteLossError",
    "Scorer",
    "TrainConfig",
    "Trainer",
    "TrainingData",
    "TrainingDataError",
    "WindowBatches",
    "WindowDataset",
    "WindowLoss",
    "build_optimizer",
    "collate_windows",
    "learning_rate",
    "load_config",
    "load_training_data",
    "train",
]
