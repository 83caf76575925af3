//! The container image and the Kubernetes manifests agree with the workspace: the Dockerfile
//! builds with the toolchain the crates require (a `docker build` cannot run on every machine,
//! so what it depends on is checked here), and every job runs the image the kustomization names.

use std::path::Path;

fn repository_file(name: &str) -> String {
    let path = Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("../..")
        .join(name);
    std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()))
}

/// The value of `key = "…"` in a TOML text.
fn toml_string(text: &str, key: &str) -> String {
    text.lines()
        .find_map(|l| {
            l.strip_prefix(key)?
                .trim()
                .strip_prefix('=')?
                .trim()
                .strip_prefix('"')
        })
        .and_then(|rest| rest.strip_suffix('"'))
        .unwrap_or_else(|| panic!("no {key} = \"…\""))
        .to_string()
}

#[test]
fn the_dockerfile_builds_with_the_workspace_toolchain_and_lock() {
    let rust_version = toml_string(&repository_file("Cargo.toml"), "rust-version");
    let docker = repository_file("Dockerfile");
    let build_stage = docker
        .lines()
        .find(|l| l.starts_with("FROM rust:"))
        .expect("a rust build stage");
    assert!(
        build_stage.starts_with(&format!("FROM rust:{rust_version}-bookworm ")),
        "{build_stage}: the workspace needs rust {rust_version} (Cargo.toml rust-version)"
    );
    assert!(
        docker.contains("ARG RUNTIME=debian:bookworm-slim"),
        "runtime image"
    );
    assert!(
        docker.contains("cargo build --release --locked"),
        "a locked release build"
    );
    assert!(docker.contains("ENTRYPOINT [\"seasonstereo\"]"));
}

#[test]
fn every_job_runs_the_image_the_kustomization_names() {
    let kustomization = repository_file("docs/jobs/kustomization.yaml");
    assert!(
        kustomization.contains("- name: seasonstereo"),
        "{kustomization}"
    );
    let mut jobs = 0;
    for manifest in [
        "docs/jobs/reconstruct-k8s.yaml",
        "docs/jobs/reconstruct-many-k8s.yaml",
        "docs/jobs/k8s-indexed-job.yaml",
    ] {
        assert!(kustomization.contains(&format!("- {}", &manifest["docs/jobs/".len()..])));
        for line in repository_file(manifest).lines() {
            let Some(image) = line.trim().strip_prefix("image:") else {
                continue;
            };
            let image = image.split('#').next().unwrap().trim();
            // The merge Job's waiting step runs kubectl; every seasonstereo step runs the image.
            assert!(
                image == "seasonstereo" || image.starts_with("bitnami/kubectl"),
                "{manifest}: image {image}"
            );
            jobs += (image == "seasonstereo") as usize;
        }
    }
    assert!(
        jobs >= 5,
        "tile pods, merge, many-date tiles and fusion, dataset: {jobs}"
    );
}
