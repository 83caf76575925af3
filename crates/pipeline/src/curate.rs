//! `curate`: consistency scores of candidate synchronic pairs and the selected top-K intersection.
