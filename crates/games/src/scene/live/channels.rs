//! The scene channels on a Foxglove WebSocket server: the same topics, JSON Schemas and JSON
//! messages a log's scene channels have, and the field for whoever subscribes late.

use std::sync::{Arc, Condvar, Mutex, PoisonError};

use ::foxglove::websocket::{ChannelView, Client, ServerListener};
use ::foxglove::{Context, PartialMetadata, RawChannel, Schema};
use anyhow::{Context as _, Result};
use serde::Serialize;
use strata_log::RecordSchema;
use strata_runtime::Time;

use crate::scene::foxglove::{frame_transforms_schema, log_schema, scene_update_schema};
use crate::scene::plot::{PLOT_TOPIC, layer_plot_schema};
use crate::scene::{EVENTS_TOPIC, FIELD_TOPIC, OBJECTS_TOPIC, SceneOutput, TRANSFORMS_TOPIC};

/// The newest field message and its time.
type LatestField = Arc<Mutex<Option<(Vec<u8>, Time)>>>;

/// One channel per scene topic, in a context of their own.
#[derive(Debug)]
pub(super) struct SceneChannels {
    /// The server and the channels hold it weakly only: it must live as long as they serve.
    context: Arc<Context>,
    field: Arc<RawChannel>,
    objects: Arc<RawChannel>,
    transforms: Arc<RawChannel>,
    events: Arc<RawChannel>,
    plot: Arc<RawChannel>,
    /// The newest field message and its time: the field is published once, so a client that
    /// subscribes later gets it from here.
    latest_field: LatestField,
}

fn channel(context: &Arc<Context>, topic: &str, schema: RecordSchema) -> Result<Arc<RawChannel>> {
    let schema = Schema::new(schema.name, "jsonschema", schema.json_schema.as_bytes());
    context
        .channel_builder(topic)
        .message_encoding("json")
        .schema(schema)
        .build_raw()
        .with_context(|| format!("creating the channel {topic}"))
}

/// The message's time for Foxglove: the run's time, as the log's messages have.
fn meta(time: Time) -> PartialMetadata {
    PartialMetadata::with_log_time(time.as_nanos())
}

impl SceneChannels {
    /// The channels in a context of their own (a process may serve several runs).
    pub(super) fn new() -> Result<SceneChannels> {
        let context = Context::new();
        Ok(SceneChannels {
            field: channel(&context, FIELD_TOPIC, scene_update_schema())?,
            objects: channel(&context, OBJECTS_TOPIC, scene_update_schema())?,
            transforms: channel(&context, TRANSFORMS_TOPIC, frame_transforms_schema())?,
            events: channel(&context, EVENTS_TOPIC, log_schema())?,
            plot: channel(&context, PLOT_TOPIC, layer_plot_schema())?,
            context,
            latest_field: Arc::default(),
        })
    }

    pub(super) fn context(&self) -> &Arc<Context> {
        &self.context
    }

    /// What tells the server's clients about the field and the subscriptions.
    pub(super) fn listener(&self, subscribed: Arc<Subscribed>) -> Arc<dyn ServerListener> {
        Arc::new(Listener {
            field: Arc::clone(&self.field),
            latest_field: Arc::clone(&self.latest_field),
            subscribed,
        })
    }

    /// Publishes what the scene says to write at `time` to the clients subscribed. Messages
    /// nobody subscribed to are not even serialized, except the field, kept for later.
    pub(super) fn publish(&self, out: &SceneOutput, time: Time) {
        if let Some(field) = &out.field
            && let Some(bytes) = json(field)
        {
            // Stored before it is published: a client subscribing meanwhile gets it from one
            // or the other (or both, which replaces the entity with itself).
            *self.latest_field.lock().unwrap_or_else(PoisonError::into_inner) =
                Some((bytes.clone(), time));
            self.field.log_with_meta(&bytes, meta(time));
        }
        send(&self.objects, out.objects.as_ref(), time);
        send(&self.transforms, out.transforms.as_ref(), time);
        send(&self.plot, out.plot.as_ref(), time);
        for line in &out.logs {
            send(&self.events, Some(line), time);
        }
    }

    /// Closes the channels: the server tells its clients they are gone.
    pub(super) fn close(&self) {
        for channel in [&self.field, &self.objects, &self.transforms, &self.events, &self.plot] {
            channel.close();
        }
    }
}

fn json(value: &impl Serialize) -> Option<Vec<u8>> {
    // The scene's own types always serialize; a failure would be a bug, reported rather than
    // hidden, and costs the live view one message.
    serde_json::to_vec(value)
        .inspect_err(|error| tracing::warn!("a scene message did not serialize: {error}"))
        .ok()
}

fn send(channel: &RawChannel, value: Option<&impl Serialize>, time: Time) {
    if let Some(value) = value
        && channel.has_sinks()
        && let Some(bytes) = json(value)
    {
        channel.log_with_meta(&bytes, meta(time));
    }
}

/// Whether a client has subscribed to anything yet, for a run that waits for one.
#[derive(Debug, Default)]
pub(super) struct Subscribed {
    any: Mutex<bool>,
    changed: Condvar,
}

impl Subscribed {
    /// Waits up to `limit` for a first subscription; true once there was one.
    pub(super) fn wait(&self, limit: std::time::Duration) -> bool {
        let any = self.any.lock().unwrap_or_else(PoisonError::into_inner);
        let (any, _) = self
            .changed
            .wait_timeout_while(any, limit, |any| !*any)
            .unwrap_or_else(PoisonError::into_inner);
        *any
    }

    fn set(&self) {
        *self.any.lock().unwrap_or_else(PoisonError::into_inner) = true;
        self.changed.notify_all();
    }
}

/// Sends the field to each new subscriber of its channel, and notes subscriptions. Runs on
/// the server's own threads and must not block: both take a short lock only.
struct Listener {
    field: Arc<RawChannel>,
    latest_field: LatestField,
    subscribed: Arc<Subscribed>,
}

impl ServerListener for Listener {
    fn on_subscribe(&self, client: Client, channel: ChannelView<'_>) {
        if channel.id() == self.field.id() {
            let latest = self.latest_field.lock().unwrap_or_else(PoisonError::into_inner).clone();
            if let Some((bytes, time)) = latest {
                self.field.log_with_meta_to_sink(&bytes, meta(time), client.sink_id());
            }
        }
        self.subscribed.set();
    }
}
