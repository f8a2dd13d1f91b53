//! The dataset format shared by the Rust collector and the PyTorch trainer, and the bridge that runs the trainer.
