//! Binary morphology on masks: connected components, small-component removal, hole filling, dilation.
