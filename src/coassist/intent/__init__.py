"""Human-intent prediction (thesis ch. 4): features, the LSTM+FC network, training,
transfer, evaluation against baselines, and the real-time predictor."""

from coassist.intent.baselines import RidgeBaseline, constant_velocity_prediction, nominal_prediction
from coassist.intent.evaluation import PREDICTORS, ModelEvaluation, evaluate_model, results_table
from coassist.intent.features import Scaler, WindowConfig, WindowSet, feature_names, split_trials, trial_features
from coassist.intent.model import IntentModel, ModelFileError, ModelMismatchError, load_model, save_model
from coassist.intent.network import IntentNet, NetworkConfig
from coassist.intent.presets import MODEL_PRESETS, Preset, TrainConfig
from coassist.intent.realtime import ModelIntent, RealtimeConfig, RealtimePredictor, load_model_intent
from coassist.intent.training import plot_losses, train_model, write_model
from coassist.intent.trials import LabeledTrial, load_trials

__all__ = [
    "PREDICTORS",
    "MODEL_PRESETS",
    "IntentModel",
    "IntentNet",
    "LabeledTrial",
    "ModelIntent",
    "ModelFileError",
    "ModelMismatchError",
    "NetworkConfig",
    "Preset",
    "RealtimeConfig",
    "RealtimePredictor",
    "RidgeBaseline",
    "Scaler",
    "TrainConfig",
    "WindowConfig",
    "WindowSet",
    "constant_velocity_prediction",
    "evaluate_model",
    "feature_names",
    "load_model_intent",
    "load_model",
    "load_trials",
    "nominal_prediction",
    "plot_losses",
    "results_table",
    "ModelEvaluation",
    "save_model",
    "split_trials",
    "train_model",
    "trial_features",
    "write_model",
]
