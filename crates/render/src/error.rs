//! The error enum of the crate.

/// Everything that can go wrong in `actrack-render`. All of these come from invalid input
/// (calibrations, image sizes, parameters); the likelihood itself never fails on a bad pose.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RenderError {
    /// A camera calibration is unusable (non-finite value, non-positive focal length, zero
    /// image size, a rotation that is not orthonormal with determinant +1, …).
    #[error("invalid camera: {0}")]
    InvalidCamera(String),
    /// An image is empty or its buffer does not match its width and height.
    #[error("invalid image: {0}")]
    InvalidImage(String),
    /// A parameter is out of range (γ ≤ 0, negative radius, …); the message says which.
    #[error("invalid parameter: {0}")]
    InvalidParameter(String),
    /// The number of edge images differs from the number of cameras.
    #[error("expected one edge image per camera ({expected}), got {got}")]
    ViewCount {
        /// Number of cameras of the model.
        expected: usize,
        /// Number of edge images passed.
        got: usize,
    },
    /// An edge image does not have its camera's size.
    #[error("edge image of view {view} is {got_w}×{got_h} but the camera is {width}×{height}")]
    ViewSize {
        /// Index of the view.
        view: usize,
        /// Camera width.
        width: u32,
        /// Camera height.
        height: u32,
        /// Edge image width.
        got_w: u32,
        /// Edge image height.
        got_h: u32,
    },
    /// The output slice of a batch call has the wrong length.
    #[error("output slice has length {got}, expected {expected}")]
    OutputLength {
        /// Number of poses.
        expected: usize,
        /// Length of the output slice.
        got: usize,
    },
}
