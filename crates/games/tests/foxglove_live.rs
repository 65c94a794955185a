//! The live scene over Foxglove's WebSocket protocol: a client connects to a lockstep match as
//! the Foxglove app does, is told the server and its channels, subscribes, and gets the
//! scene's JSON messages; a client sending garbage disturbs neither the server nor the match.

use std::collections::BTreeSet;
use std::net::{SocketAddr, TcpStream};
use std::time::Duration;

use serde_json::Value;
use strata_games::matches::{Match, MatchConfig};
use strata_games::scene::live::SceneServer;
use strata_games::scene::{FIELD_TOPIC, OBJECTS_TOPIC};
use tungstenite::client::IntoClientRequest;
use tungstenite::http::HeaderValue;
use tungstenite::{Message, WebSocket};

/// The subprotocol the official SDK's server speaks and today's Foxglove app asks for.
const SUBPROTOCOL: &str = "foxglove.sdk.v1";

/// Long enough for a loaded machine; a client that gets nothing fails instead of hanging.
const PATIENCE: Duration = Duration::from_secs(120);

fn connect(addr: SocketAddr) -> WebSocket<TcpStream> {
    let stream = TcpStream::connect(addr).expect("the server accepts connections");
    stream.set_read_timeout(Some(PATIENCE)).expect("a read timeout");
    let mut request = format!("ws://{addr}").into_client_request().expect("a request");
    request.headers_mut().insert("Sec-WebSocket-Protocol", HeaderValue::from_static(SUBPROTOCOL));
    let (socket, response) = tungstenite::client(request, stream).expect("the handshake");
    let protocol = response.headers().get("Sec-WebSocket-Protocol");
    assert_eq!(protocol.and_then(|p| p.to_str().ok()), Some(SUBPROTOCOL));
    socket
}

/// The next JSON message the server sends as text.
fn next_json(socket: &mut WebSocket<TcpStream>) -> Value {
    loop {
        match socket.read().expect("a message before the read timeout") {
            Message::Text(text) => return serde_json::from_str(&text).expect("JSON"),
            Message::Binary(_) | Message::Ping(_) | Message::Pong(_) | Message::Frame(_) => {}
            Message::Close(frame) => panic!("the server closed the connection: {frame:?}"),
        }
    }
}

/// A client that sends what no Foxglove client would, then leaves once the server has
/// answered the last of it (or dropped the client, which is its right).
fn send_garbage(addr: SocketAddr) {
    let mut socket = connect(addr);
    let junk = [
        Message::text("this is not JSON"),
        Message::text(r#"{"op":"noSuchOperation"}"#),
        Message::text(r#"{"op":"subscribe","subscriptions":"not a list"}"#),
        Message::text(r#"{"op":"unsubscribe","subscriptionIds":[12345]}"#),
        Message::text(r#"[1, 2, 3]"#),
        Message::binary(vec![0xff, 0x00, 0x13, 0x37]),
        Message::binary(vec![0x01]),
        Message::binary(Vec::new()),
        // Answered with an error status: the server has read everything before it.
        Message::text(r#"{"op":"subscribe","subscriptions":[{"id":1,"channelId":999999}]}"#),
    ];
    for message in junk {
        if socket.send(message).is_err() {
            return;
        }
    }
    loop {
        match socket.read() {
            Ok(Message::Text(text)) => {
                let status: Value = serde_json::from_str(&text).expect("the server writes JSON");
                let message = status["message"].as_str().unwrap_or_default();
                if status["op"] == "status" && message.contains("999999") {
                    break;
                }
            }
            Ok(Message::Close(_)) | Err(_) => return,
            Ok(_) => {}
        }
    }
    let _ = socket.close(None);
}

/// What the test client saw of the live match.
struct Seen {
    field_entities: Vec<String>,
    objects_entities: BTreeSet<String>,
}

/// Subscribes to the objects and the field and reads until it has both, the objects with the
/// ball and every robot's true pose and estimate.
fn watch(addr: SocketAddr, robots: &[&str]) -> Seen {
    let mut socket = connect(addr);
    let info = next_json(&mut socket);
    assert_eq!(info["op"], "serverInfo", "{info}");
    assert_eq!(info["name"], "strata", "{info}");
    let capabilities = info["capabilities"].as_array().expect("capabilities");
    assert!(capabilities.iter().any(|c| c == "time"), "{info}");

    let advertise = next_json(&mut socket);
    assert_eq!(advertise["op"], "advertise", "{advertise}");
    let channels = advertise["channels"].as_array().expect("channels");
    let channel = |topic: &str| {
        channels.iter().find(|c| c["topic"] == topic).unwrap_or_else(|| panic!("{topic}"))
    };
    for (topic, schema) in [
        (FIELD_TOPIC, "foxglove.SceneUpdate"),
        (OBJECTS_TOPIC, "foxglove.SceneUpdate"),
        ("scene/tf", "foxglove.FrameTransforms"),
        ("scene/events", "foxglove.Log"),
        ("plot/layers", "strata.LayerPlot"),
    ] {
        let c = channel(topic);
        assert_eq!(c["schemaName"], schema, "{c}");
        assert_eq!(c["encoding"], "json", "{c}");
        assert_eq!(c["schemaEncoding"], "jsonschema", "{c}");
        let text = c["schema"].as_str().expect("the schema inline");
        let schema: Value = serde_json::from_str(text).expect("a JSON Schema");
        assert_eq!(schema["type"], "object", "{topic}");
    }
    // The objects first: the match starts at the first subscription, and the field is sent
    // to a late subscriber anyway.
    let (objects, field) = (&channel(OBJECTS_TOPIC)["id"], &channel(FIELD_TOPIC)["id"]);
    let subscribe = serde_json::json!({
        "op": "subscribe",
        "subscriptions": [{ "id": 1, "channelId": objects }, { "id": 2, "channelId": field }],
    });
    socket.send(Message::text(subscribe.to_string())).expect("subscribed");

    let mut field_entities = None;
    let mut objects_entities = None;
    while field_entities.is_none() || objects_entities.is_none() {
        let bytes = match socket.read().expect("scene messages before the read timeout") {
            Message::Binary(bytes) => bytes,
            Message::Close(frame) => panic!("the server closed the connection: {frame:?}"),
            _ => continue,
        };
        // Message data: opcode 1, subscription id (u32), log time (u64), the message.
        if bytes.first() != Some(&1) {
            continue;
        }
        assert!(bytes.len() > 13, "a message data frame of {} bytes", bytes.len());
        let subscription = u32::from_le_bytes(bytes[1..5].try_into().expect("4 bytes"));
        let update: Value = serde_json::from_slice(&bytes[13..]).expect("a JSON SceneUpdate");
        let ids: Vec<String> = update["entities"]
            .as_array()
            .expect("entities")
            .iter()
            .map(|e| e["id"].as_str().expect("an id").to_owned())
            .collect();
        match subscription {
            1 => {
                let ids: BTreeSet<String> = ids.into_iter().collect();
                let complete = ids.contains("ball")
                    && robots.iter().all(|r| {
                        ids.contains(&format!("{r}/truth"))
                            && ids.contains(&format!("{r}/estimate"))
                    });
                if complete {
                    objects_entities = Some(ids);
                }
            }
            2 => field_entities = Some(ids),
            other => panic!("a message for subscription {other}"),
        }
    }
    let _ = socket.close(None);
    Seen {
        field_entities: field_entities.unwrap_or_default(),
        objects_entities: objects_entities.unwrap_or_default(),
    }
}

/// The entity ids of the first `scene/field` message a client gets that subscribes after the
/// field was published.
fn late_field(addr: SocketAddr) -> Vec<String> {
    let mut socket = connect(addr);
    let _info = next_json(&mut socket);
    let advertise = next_json(&mut socket);
    let channels = advertise["channels"].as_array().expect("channels");
    let field = channels.iter().find(|c| c["topic"] == FIELD_TOPIC).expect("the field's channel");
    let subscribe = serde_json::json!({
        "op": "subscribe",
        "subscriptions": [{ "id": 7, "channelId": field["id"] }],
    });
    socket.send(Message::text(subscribe.to_string())).expect("subscribed");
    loop {
        let bytes = match socket.read().expect("the field before the read timeout") {
            Message::Binary(bytes) => bytes,
            Message::Close(frame) => panic!("the server closed the connection: {frame:?}"),
            _ => continue,
        };
        if bytes.first() == Some(&1) && bytes.len() > 13 {
            let update: Value = serde_json::from_slice(&bytes[13..]).expect("a JSON SceneUpdate");
            let _ = socket.close(None);
            return update["entities"]
                .as_array()
                .expect("entities")
                .iter()
                .map(|e| e["id"].as_str().expect("an id").to_owned())
                .collect();
        }
    }
}

#[test]
fn a_foxglove_client_subscribes_to_a_live_match_and_gets_its_scene() {
    let config = MatchConfig { players: 2, seed: 3, limit: Some(6.0), ..MatchConfig::default() };
    let mut game = Match::new(config).expect("a valid match");
    let any_port: SocketAddr = "127.0.0.1:0".parse().expect("an address");
    let mut server = SceneServer::attach(&mut game, any_port, None).expect("the server starts");
    let addr = server.addr();
    assert_ne!(addr.port(), 0, "the port the system chose");

    send_garbage(addr);
    let robots = ["home/1", "home/2", "away/1", "away/2"];
    let client = std::thread::spawn(move || watch(addr, &robots));
    assert!(server.wait_for_subscriber(PATIENCE), "a client subscribed");
    let report = game.play(&mut |_, _| {}).expect("the match runs");
    assert!(report.simulated_s > 5.0, "the match was played: {report:?}");
    let seen = client.join().expect("the client read the scene");
    // The match is over and the field was published long ago: it is sent on subscription.
    assert_eq!(late_field(addr), ["field"], "a late subscriber gets the field");
    server.finish();

    assert_eq!(seen.field_entities, ["field"]);
    assert!(seen.objects_entities.contains("home/1/view"), "{:?}", seen.objects_entities);
}
