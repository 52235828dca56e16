//! docs/foxglove-layout.json is valid JSON and names only topics the view advertises.

use milliego_live_view::TOPICS;

#[test]
fn the_layout_names_only_advertised_topics() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../docs/foxglove-layout.json");
    let text = std::fs::read_to_string(path).unwrap();
    let j: serde_json::Value = serde_json::from_str(&text).expect("layout is JSON");
    let panels = j["configById"].as_object().expect("configById");
    let mut named = Vec::new();
    for (id, cfg) in panels {
        if let Some(topics) = cfg["topics"].as_object() {
            named.extend(topics.keys().cloned());
        }
        for p in cfg["paths"].as_array().into_iter().flatten() {
            let v = p["value"].as_str().unwrap();
            named.push(v.split('.').next().unwrap().to_string());
        }
        if let Some(t) = cfg["topicPath"].as_str() {
            named.push(t.to_string());
        }
        assert!(
            j["layout"].to_string().contains(id.as_str()),
            "panel {id} is not in the layout tree"
        );
    }
    assert!(named.len() >= 8, "{named:?}");
    for t in &named {
        assert!(
            TOPICS.contains(&t.as_str()),
            "{t} is not a topic of the view"
        );
    }
    for t in [
        "/radar/points",
        "/trajectory",
        "/velocity",
        "/imu",
        "/health",
    ] {
        assert!(named.iter().any(|n| n == t), "the layout shows no {t}");
    }
}
