"""Trial logs, datasets on disk, and the loader for real UR5 recordings."""

from coassist.data.datasets import (
    Dataset,
    DatasetWriter,
    TrialFileError,
    append_to_dataset,
    read_dataset,
    read_trial,
    write_dataset,
    write_trial,
)
from coassist.data.rosbag_csv import (
    RecordingError,
    RecordingWarning,
    default_real_data,
    load_ros_trial,
    load_ros_user,
)
from coassist.data.trial import Trial, TrialMeta

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
