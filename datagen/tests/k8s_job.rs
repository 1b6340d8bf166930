//! `deploy/k8s/datagen-job.yaml` against the Kubernetes API's own types of a current release
//! (`k8s-openapi`, generated from the API's OpenAPI specification, `latest` = 1.37), offline:
//! the file reads as a `batch/v1` Job and reads back to exactly itself (so no field is unknown
//! to the API, misspelt or misplaced, since those would be dropped), and the sharding it sets up
//! is the one `datagen render` reads: an Indexed Job whose `DATAGEN_SHARD_COUNT` equals
//! `spec.completions` (the binary's reading of `JOB_COMPLETION_INDEX` and `DATAGEN_SHARD_COUNT`
//! is tested in `config_plan_families.rs`).

use k8s_openapi::api::batch::v1::Job;
use std::path::Path;

fn job_file() -> (String, serde_json::Value) {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../deploy/k8s/datagen-job.yaml");
    let text = std::fs::read_to_string(&path).unwrap();
    let value: serde_json::Value = serde_norway::from_str(&text)
        .unwrap_or_else(|e| panic!("{}: not YAML: {e}", path.display()));
    (path.display().to_string(), value)
}

#[test]
fn the_job_file_is_a_valid_kubernetes_job_that_reads_back_to_itself() {
    let (path, value) = job_file();
    let job: Job = serde_json::from_value(value.clone())
        .unwrap_or_else(|e| panic!("{path}: not a batch/v1 Job: {e}"));
    let back = serde_json::to_value(&job).unwrap();
    assert_eq!(
        back, value,
        "{path}: fields the Kubernetes API does not know were dropped"
    );
    // And the API's types do see a misspelt field as one: the check can fail.
    let mut typo = value.clone();
    typo["spec"]["completion"] = typo["spec"]["completions"].take();
    let job: Job = serde_json::from_value(typo.clone()).unwrap();
    assert_ne!(serde_json::to_value(&job).unwrap(), typo);
}

#[test]
fn the_job_shards_as_datagen_reads_it() {
    let (path, value) = job_file();
    let job: Job = serde_json::from_value(value).unwrap();
    let spec = job.spec.expect("a job spec");
    assert_eq!(spec.completion_mode.as_deref(), Some("Indexed"), "{path}");
    let completions = spec.completions.expect("completions");
    let pod = spec.template.spec.expect("a pod spec");
    let container = &pod.containers[0];
    let count = container
        .env
        .iter()
        .flatten()
        .find(|e| e.name == "DATAGEN_SHARD_COUNT")
        .and_then(|e| e.value.clone())
        .expect("DATAGEN_SHARD_COUNT is set");
    assert_eq!(
        count,
        completions.to_string(),
        "{path}: shard count != completions"
    );
    assert_eq!(pod.restart_policy.as_deref(), Some("Never"), "{path}");
    let args = container.args.clone().unwrap_or_default();
    assert_eq!(args.first().map(String::as_str), Some("render"), "{path}");
    assert!(args.iter().any(|a| a == "--out") && args.iter().any(|a| a == "--config"));
}
