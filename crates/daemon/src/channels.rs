//! The channels of a session: the topics, their encodings and schemas,
//! shared by the recording ([`crate::record`]) and the live view
//! ([`crate::viewer`], which documents what each carries).

use foxglove::Encode;
use foxglove::messages as fm;

/// The session's channels.
#[derive(Copy, Clone, Debug, PartialEq, Eq)]
#[repr(usize)]
pub enum Topic {
    /// `/view/cell`: the table, the robot base, its workspace and the hitting window.
    Cell,
    /// `/tf`: the transform from the `table` frame to `robot_base`.
    Tf,
    /// `/view/ball`: the observations, the EKF estimate, the predicted path, spin and logo.
    Ball,
    /// `/view/robot`: the planned bat, the actual and commanded arm and TCP.
    Robot,
    /// `/view/plan_pose`: the planned bat pose in the `table` frame.
    PlanPose,
    /// `/view/tcp`: the actual and commanded TCP poses in `robot_base`.
    Tcp,
    /// `/view/verdict`: hit or miss per ball (the demo only).
    Verdict,
    /// `/plot/spin`: the EKF spin per observation.
    Spin,
    /// `/plot/prediction_error`: each plan's error when a ball ends.
    PredictionError,
    /// `/plot/rsi`: latency and counters per RSI answer.
    Rsi,
    /// `/plot/queues`: the depths of the telemetry queues.
    Queues,
    /// `/logo/crop`: the logo thread's crop image.
    LogoCrop,
    /// `/logo/fit`: the ball and the detected logo drawn on the crop.
    LogoFit,
}

/// Every viewer channel, in the order of [`Topic`]'s discriminants.
pub const TOPICS: [Topic; 13] = [
    Topic::Cell,
    Topic::Tf,
    Topic::Ball,
    Topic::Robot,
    Topic::PlanPose,
    Topic::Tcp,
    Topic::Verdict,
    Topic::Spin,
    Topic::PredictionError,
    Topic::Rsi,
    Topic::Queues,
    Topic::LogoCrop,
    Topic::LogoFit,
];

fn proto_schema<T: Encode>() -> foxglove::Schema {
    T::get_schema().expect("foxglove's well-known schemas have a schema")
}

fn json_schema(name: &str, properties: &str) -> foxglove::Schema {
    let text = format!(
        r#"{{"$schema":"https://json-schema.org/draft/2020-12/schema","title":"{name}","type":"object","properties":{properties}}}"#
    );
    foxglove::Schema::new(name, "jsonschema", text.into_bytes())
}

impl Topic {
    /// The channel's topic.
    pub fn name(self) -> &'static str {
        match self {
            Topic::Cell => "/view/cell",
            Topic::Tf => "/tf",
            Topic::Ball => "/view/ball",
            Topic::Robot => "/view/robot",
            Topic::PlanPose => "/view/plan_pose",
            Topic::Tcp => "/view/tcp",
            Topic::Verdict => "/view/verdict",
            Topic::Spin => "/plot/spin",
            Topic::PredictionError => "/plot/prediction_error",
            Topic::Rsi => "/plot/rsi",
            Topic::Queues => "/plot/queues",
            Topic::LogoCrop => "/logo/crop",
            Topic::LogoFit => "/logo/fit",
        }
    }

    /// The message encoding: `protobuf` or `json`.
    pub fn encoding(self) -> &'static str {
        match self {
            Topic::Spin | Topic::PredictionError | Topic::Rsi | Topic::Queues => "json",
            _ => "protobuf",
        }
    }

    /// The schema (name, encoding, data) of the channel.
    pub fn schema(self) -> foxglove::Schema {
        let n = r#"{"type":"number"}"#;
        let i = r#"{"type":"integer"}"#;
        match self {
            Topic::Cell | Topic::Ball | Topic::Robot | Topic::Verdict => proto_schema::<fm::SceneUpdate>(),
            Topic::Tf => proto_schema::<fm::FrameTransform>(),
            Topic::PlanPose => proto_schema::<fm::PoseInFrame>(),
            Topic::Tcp => proto_schema::<fm::PosesInFrame>(),
            Topic::LogoCrop => proto_schema::<fm::RawImage>(),
            Topic::LogoFit => proto_schema::<fm::ImageAnnotations>(),
            Topic::Spin => json_schema(
                "topspin.SpinPlot",
                &format!(r#"{{"trajectory":{i},"x_rps":{n},"y_rps":{n},"z_rps":{n},"norm_rps":{n}}}"#),
            ),
            Topic::PredictionError => json_schema(
                "topspin.PredictionErrorPlot",
                &format!(
                    r#"{{"trajectory":{i},"seq":{i},"time_to_hit_s":{n},"error_mm":{n},"dt_ms":{n},"reference":{{"type":"string"}}}}"#
                ),
            ),
            Topic::Rsi => json_schema(
                "topspin.RsiPlot",
                &format!(
                    r#"{{"latency_us":{i},"controller_late":{i},"slow_answers":{i},"plans_late":{i},"plans_rejected":{i}}}"#
                ),
            ),
            Topic::Queues => json_schema(
                "topspin.QueuePlot",
                &format!(r#"{{"rings":{{"type":"array","items":{i}}},"rsi_bytes":{i},"dropped":{i}}}"#),
            ),
        }
    }
}
