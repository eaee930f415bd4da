pub use caustics_core;
