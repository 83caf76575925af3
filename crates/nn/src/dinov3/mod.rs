//! DINOv3 ViT image features and the curation similarity score.
