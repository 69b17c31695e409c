"""Trial logs, datasets on disk, and the loader for real UR5 recordings."""

from coassist.data.datasets import Dataset, DatasetWriter, append_to_dataset, read_dataset, write_dataset
from coassist.data.rosbag_csv import (
    RecordingError,
    RecordingWarning,
    default_real_data,
    load_ros_trial,
    load_ros_user,
)
from coassist.data.trial import Trial, TrialMeta
from coassist.data.trial_file import TrialFileError, read_trial, write_trial

__all__ = [
    "Dataset",
    "DatasetWriter",
    "RecordingError",
    "RecordingWarning",
    "Trial",
    "TrialFileError",
    "TrialMeta",
    "append_to_dataset",
    "default_real_data",
    "load_ros_trial",
    "load_ros_user",
    "read_dataset",
    "read_trial",
    "write_dataset",
    "write_trial",
]
